//! Frames: the images of one instant of the rig, as every layer that touches pixels sees them.
//!
//! In: a [`Rig`] (its sensors' ids and sizes). Out: [`FrameSet`] — one [`SensorImage`] per
//! sensor, an RGB8 buffer of exactly the sensor's size with its capture time, whether the sensor
//! delivered for this frame and, if not, why ([`ImageFault`]).
//!
//! Plain data, no I/O: the capture layer (`omnitrack-io`) fills frames, the edge stage reads
//! them, and neither needs the other's dependencies (the edge stage links no transport).
//!
//! Memory: [`FrameSet::for_rig`] allocates every buffer once; nothing here allocates afterwards,
//! and a buffer's length never changes (a boxed slice).
//!
//! Failure: a sensor's image is marked invalid with a fault, never an error. The accessors that
//! take an index ([`SensorImage::rgb`], [`FrameSet::sensor`]) panic outside the image or the rig,
//! like slice indexing: callers pass indices they got from the rig.

use crate::rig::Rig;
use std::fmt;

/// Why one sensor has no usable image in a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ImageFault {
    /// The source has nothing for this sensor in this frame (a recording without a row for it, a
    /// camera that did not deliver in time).
    Dropped,
    /// The image should be there but is not: file or directory missing or unreadable.
    Missing,
    /// The image data cannot be decoded.
    Corrupt,
    /// The image is not the sensor's width × height.
    WrongSize,
    /// The image has a pixel format that cannot be turned into RGB8 (e.g. 16 bits per channel).
    WrongFormat,
}

impl ImageFault {
    /// Every fault, in the order of [`ImageFault::index`].
    pub const ALL: [ImageFault; 5] = [
        ImageFault::Dropped,
        ImageFault::Missing,
        ImageFault::Corrupt,
        ImageFault::WrongSize,
        ImageFault::WrongFormat,
    ];

    /// Position in [`ImageFault::ALL`] (for per-kind counter arrays).
    pub fn index(self) -> usize {
        self as usize
    }

    /// Short human-readable name.
    pub fn name(self) -> &'static str {
        match self {
            ImageFault::Dropped => "dropped",
            ImageFault::Missing => "missing",
            ImageFault::Corrupt => "corrupt",
            ImageFault::WrongSize => "wrong size",
            ImageFault::WrongFormat => "wrong format",
        }
    }
}

impl fmt::Display for ImageFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One sensor's image of one frame: an RGB8 buffer of exactly the sensor's size, allocated once.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorImage {
    sensor: usize,
    width: u32,
    height: u32,
    /// Row-major RGB8, `width * height * 3` bytes; a boxed slice so that it can never grow.
    pixels: Box<[u8]>,
    /// Capture time (ns) as the source knows it; 0 when the source has no record of this sensor
    /// in this frame ([`ImageFault::Dropped`]).
    pub timestamp_ns: u64,
    /// Whether this sensor delivered a usable image for this frame. When false the pixels are
    /// stale or partly overwritten and must not be used.
    pub valid: bool,
    /// Why the image is not valid; `None` when `valid`.
    pub fault: Option<ImageFault>,
}

impl SensorImage {
    /// A zeroed, not-yet-valid image for a sensor of the given size.
    pub fn new(sensor: usize, width: u32, height: u32) -> SensorImage {
        let len = width as usize * height as usize * 3;
        SensorImage {
            sensor,
            width,
            height,
            pixels: vec![0u8; len].into_boxed_slice(),
            timestamp_ns: 0,
            valid: false,
            fault: Some(ImageFault::Dropped),
        }
    }

    /// Sensor id (index in [`Rig::sensors`]).
    pub fn sensor(&self) -> usize {
        self.sensor
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    /// Row-major RGB8 pixels, `width * height * 3` bytes.
    pub fn pixels(&self) -> &[u8] {
        &self.pixels
    }

    /// Mutable pixels, for sources (and image-noise stages) that fill the buffer in place.
    pub fn pixels_mut(&mut self) -> &mut [u8] {
        &mut self.pixels
    }

    /// RGB of the pixel at column `u`, row `v`. Panics if outside the image.
    pub fn rgb(&self, u: u32, v: u32) -> [u8; 3] {
        assert!(
            u < self.width && v < self.height,
            "pixel ({u}, {v}) outside {}x{}",
            self.width,
            self.height
        );
        let i = (v as usize * self.width as usize + u as usize) * 3;
        [self.pixels[i], self.pixels[i + 1], self.pixels[i + 2]]
    }

    /// Marks the image usable, captured at `timestamp_ns`.
    pub fn set_valid(&mut self, timestamp_ns: u64) {
        self.timestamp_ns = timestamp_ns;
        self.valid = true;
        self.fault = None;
    }

    /// Marks the image unusable for `fault`; `timestamp_ns` is the capture time if known, else 0.
    pub fn set_invalid(&mut self, fault: ImageFault, timestamp_ns: u64) {
        self.timestamp_ns = timestamp_ns;
        self.valid = false;
        self.fault = Some(fault);
    }
}

/// One frame of the rig: one [`SensorImage`] per sensor, indexed by sensor id.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameSet {
    /// Frame sequence number as the source numbers it (for a recording: the `frame` column of
    /// `frames.csv`, so numbers may skip where a whole frame was dropped).
    pub sequence: u64,
    /// Indexed by sensor id; its length never changes.
    sensors: Box<[SensorImage]>,
}

impl FrameSet {
    /// Allocates the buffers for every sensor of the rig (the only allocation a frame ever needs).
    pub fn for_rig(rig: &Rig) -> FrameSet {
        FrameSet {
            sequence: 0,
            sensors: rig
                .sensors
                .iter()
                .map(|s| SensorImage::new(s.id, s.width, s.height))
                .collect(),
        }
    }

    /// Whether the buffers are the rig's: one per sensor, in id order, of each sensor's size.
    pub fn fits(&self, rig: &Rig) -> bool {
        self.sensors.len() == rig.sensors.len()
            && self
                .sensors
                .iter()
                .zip(&rig.sensors)
                .all(|(img, s)| img.sensor == s.id && img.width == s.width && img.height == s.height)
    }

    /// One image per sensor, indexed by sensor id.
    pub fn sensors(&self) -> &[SensorImage] {
        &self.sensors
    }

    /// Mutable images (the slice cannot change length).
    pub fn sensors_mut(&mut self) -> &mut [SensorImage] {
        &mut self.sensors
    }

    /// The image of sensor `id`. Panics if the rig has no such sensor.
    pub fn sensor(&self, id: usize) -> &SensorImage {
        &self.sensors[id]
    }

    pub fn sensor_mut(&mut self, id: usize) -> &mut SensorImage {
        &mut self.sensors[id]
    }

    /// Number of sensors that delivered a usable image.
    pub fn valid_count(&self) -> usize {
        self.sensors.iter().filter(|s| s.valid).count()
    }

    /// Earliest capture time among the valid images, if any is valid.
    pub fn timestamp_ns(&self) -> Option<u64> {
        self.sensors.iter().filter(|s| s.valid).map(|s| s.timestamp_ns).min()
    }
}
