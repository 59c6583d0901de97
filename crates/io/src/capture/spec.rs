//! How a frame source is opened and run: [`SourceOptions`].
//!
//! In: what the command line asks (`--realtime`) over the defaults. Out: [`SourceOptions`], how a
//! replay is paced and how long a live source waits for an image and between reopenings.
//! Opening is [`super::open`]'s; nothing here touches a file or a device. A file of its own so
//! that the live drivers and the code that picks among them both use it without using each other.

use super::replay::Pacing;
use std::time::Duration;

/// How sources are opened and run; [`SourceOptions::default`] is what `omnitrack run` uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SourceOptions {
    /// Pacing of `replay:DIR` (default: real time, like a camera).
    pub pacing: Pacing,
    /// Longest wait for one sensor's image before it counts as dropped (live sources; default 1 s).
    pub frame_timeout: Duration,
    /// How often a lost live sensor is reopened (default 1 s).
    pub reopen_interval: Duration,
}

impl Default for SourceOptions {
    fn default() -> SourceOptions {
        SourceOptions {
            pacing: Pacing::RealTime,
            frame_timeout: Duration::from_secs(1),
            reopen_interval: Duration::from_secs(1),
        }
    }
}
