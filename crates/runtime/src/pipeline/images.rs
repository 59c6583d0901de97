//! Per-sensor image buffers of per-device capture, and the note that one is ready.
//!
//! In: the rig (each sensor's size). Out: [`SensorImages`], [`IMAGES_PER_SENSOR`] preallocated
//! images per sensor with a list of the free ones, and [`Arrival`], what a capture thread sends
//! the assembly when it has filled one. The capture threads take and fill buffers
//! ([`super::capture`]); the assembly ([`super::assembly`]) moves them into pool frames and gives
//! them back. Both use this file; it uses neither.
//!
//! Memory: every buffer is allocated in [`SensorImages::new`]; taking and releasing one moves
//! only its index through a bounded channel.

use super::shared::{lock, Shared};
use super::TICK;
use crossbeam::channel::{bounded, Receiver, RecvTimeoutError, Sender};
use omnitrack_core::frame::SensorImage;
use omnitrack_core::rig::Rig;
use std::sync::{Mutex, MutexGuard};
use std::time::Instant;

/// Image buffers per sensor for per-sensor capture.
pub(super) const IMAGES_PER_SENSOR: usize = 4;

/// One sensor's image buffers (per-sensor capture) and the list of free ones.
pub(super) struct SensorImages {
    pub(super) images: Box<[Mutex<SensorImage>]>,
    free_tx: Sender<usize>,
    free_rx: Receiver<usize>,
}

impl SensorImages {
    pub(super) fn new(rig: &Rig, k: usize) -> SensorImages {
        let s = &rig.sensors[k];
        let (free_tx, free_rx) = bounded(IMAGES_PER_SENSOR);
        let images = (0..IMAGES_PER_SENSOR)
            .map(|i| {
                free_tx.send(i).expect("room for every handle");
                Mutex::new(SensorImage::new(s.id, s.width, s.height))
            })
            .collect();
        SensorImages {
            images,
            free_tx,
            free_rx,
        }
    }

    pub(super) fn image(&self, i: usize) -> MutexGuard<'_, SensorImage> {
        lock(&self.images[i])
    }

    pub(super) fn take(&self, shared: &Shared) -> Option<usize> {
        loop {
            if shared.stopping() {
                return None;
            }
            match self.free_rx.recv_timeout(TICK) {
                Ok(i) => return Some(i),
                Err(RecvTimeoutError::Timeout) => continue,
                Err(RecvTimeoutError::Disconnected) => return None,
            }
        }
    }

    pub(super) fn release(&self, i: usize) {
        let _ = self.free_tx.try_send(i);
    }
}

/// An image of one sensor, ready in its buffer `slot`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Arrival {
    pub(super) sensor: usize,
    pub(super) slot: usize,
    pub(super) arrived: Instant,
}
