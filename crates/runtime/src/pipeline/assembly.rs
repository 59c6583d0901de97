//! Frame assembly for per-sensor capture: the images of one instant, matched by timestamp.
//!
//! The first valid image opens a frame at its timestamp (the anchor). Images within the
//! tolerance of the anchor join it; an image later than that closes the frame and opens the next
//! one; an image earlier than that belongs to an instant already closed and is counted as a sync
//! miss. A failed read (an invalid image, which has no timestamp) stands for its sensor in the
//! open frame, or in the next one if that sensor is accounted for already. A frame is closed as
//! soon as every sensor has its image or a fault, or `wait` after its first image arrived.
//! Closing moves each image into a free frame of the pool by swapping buffers (the frame's old
//! buffer goes back to the sensor), marks the missing sensors invalid (with the fault their
//! camera reported, else `Dropped` and a sync miss), and hands the frame to the tracker.

use super::images::{Arrival, SensorImages};
use super::pool::{Handover, Pool};
use super::shared::{lock, Shared};
use super::stats::SensorCounters;
use crossbeam::channel::{Receiver, RecvTimeoutError};
use omnitrack_core::frame::ImageFault;
use std::time::{Duration, Instant};

pub(super) struct Assembler<'a, 'o> {
    shared: &'a Shared<'o>,
    pool: &'a Pool,
    images: &'a [SensorImages],
    handover: Handover,
    tolerance_ns: u64,
    wait: Duration,
    /// Per sensor: its image buffer in the open frame.
    pending: Box<[Option<usize>]>,
    /// Per sensor: the fault its camera reported since the last frame closed.
    faults: Box<[Option<ImageFault>]>,
    /// Anchor timestamp and first arrival of the open frame.
    open: Option<(u64, Instant)>,
    /// Anchor of the last closed frame.
    last_anchor: Option<u64>,
    seq: u64,
}

impl<'a, 'o> Assembler<'a, 'o> {
    pub(super) fn new(
        shared: &'a Shared<'o>,
        pool: &'a Pool,
        images: &'a [SensorImages],
        handover: Handover,
        tolerance: Duration,
        wait: Duration,
    ) -> Self {
        let n = images.len();
        Assembler {
            shared,
            pool,
            images,
            handover,
            tolerance_ns: tolerance.as_nanos() as u64,
            wait,
            pending: vec![None; n].into_boxed_slice(),
            faults: vec![None; n].into_boxed_slice(),
            open: None,
            last_anchor: None,
            seq: 0,
        }
    }

    /// Until every capture thread has ended (then the open frame is closed) or the pipeline stops.
    pub(super) fn run(&mut self, arrivals: Receiver<Arrival>) {
        loop {
            if self.shared.stopping() {
                break;
            }
            let now = Instant::now();
            let mut deadline = now + super::TICK;
            if let Some((_, first)) = self.open {
                deadline = deadline.min(first + self.wait);
            }
            match arrivals.recv_timeout(deadline.saturating_duration_since(now)) {
                Ok(a) => self.arrive(a),
                Err(RecvTimeoutError::Timeout) => {
                    if self.open.is_some_and(|(_, first)| Instant::now() >= first + self.wait) {
                        self.close();
                    }
                }
                Err(RecvTimeoutError::Disconnected) => {
                    if self.open.is_some() {
                        self.close();
                    }
                    break;
                }
            }
        }
    }

    fn arrive(&mut self, a: Arrival) {
        let k = a.sensor;
        let (valid, ts, fault) = {
            let img = self.images[k].image(a.slot);
            (img.valid, img.timestamp_ns, img.fault)
        };
        if !valid {
            // Counted as a fault by the capture thread; stands for this sensor's image in the
            // open frame, or, if that one has its image or fault already, in the next.
            self.images[k].release(a.slot);
            if self.open.is_some() && self.accounted(k) {
                self.close();
            }
            self.faults[k] = Some(fault.unwrap_or(ImageFault::Dropped));
            if self.open.is_some() && self.complete() {
                self.close();
            }
            return;
        }
        let tol = self.tolerance_ns;
        match self.open {
            None if self.last_anchor.is_some_and(|last| ts <= last.saturating_add(tol)) => {
                self.missed(k, a.slot);
                return;
            }
            None => self.start(k, a, ts),
            Some((anchor, _)) if ts > anchor.saturating_add(tol) => {
                self.close();
                self.start(k, a, ts);
            }
            Some((anchor, _)) if ts.saturating_add(tol) < anchor => {
                self.missed(k, a.slot);
                return;
            }
            Some(_) => {
                // An image wins over a fault reported for this sensor meanwhile.
                self.faults[k] = None;
                if let Some(old) = self.pending[k].replace(a.slot) {
                    // A second image of the same instant: the newer one wins.
                    SensorCounters::add(&self.shared.sensors[k].overwritten, 1);
                    self.images[k].release(old);
                }
            }
        }
        if self.complete() {
            self.close();
        }
    }

    /// Whether sensor `k` has its image or a fault in the open frame.
    fn accounted(&self, k: usize) -> bool {
        self.pending[k].is_some() || self.faults[k].is_some()
    }

    /// Every sensor has its image or a fault: nothing more to wait for.
    fn complete(&self) -> bool {
        (0..self.pending.len()).all(|k| self.accounted(k))
    }

    fn start(&mut self, k: usize, a: Arrival, ts: u64) {
        self.open = Some((ts, a.arrived));
        self.pending[k] = Some(a.slot);
    }

    /// An image whose instant is already closed.
    fn missed(&mut self, k: usize, slot: usize) {
        SensorCounters::add(&self.shared.sensors[k].sync_missed, 1);
        self.images[k].release(slot);
    }

    /// Closes the open frame: into a pool frame and on to the tracker.
    fn close(&mut self) {
        let Some((anchor, first)) = self.open.take() else {
            return;
        };
        self.last_anchor = Some(anchor);
        // The pool has a free frame unless the tracker holds them all; wait a little for one.
        let h = match self.pool.free_rx.try_recv() {
            Ok(h) => Some(h),
            Err(_) => self.pool.free_rx.recv_timeout(self.wait).ok(),
        };
        let Some(h) = h else {
            // No frame to put it in: every image of it is lost, counted.
            for (k, p) in self.pending.iter_mut().enumerate() {
                if let Some(i) = p.take() {
                    SensorCounters::add(&self.shared.sensors[k].overwritten, 1);
                    self.images[k].release(i);
                }
                self.faults[k] = None;
            }
            return;
        };
        {
            let mut slot = self.pool.slot(h);
            for k in 0..self.pending.len() {
                let target = slot.frame.sensor_mut(k);
                match self.pending[k].take() {
                    Some(i) => {
                        let mut img = lock(&self.images[k].images[i]);
                        std::mem::swap(&mut *img, target);
                        drop(img);
                        self.images[k].release(i);
                    }
                    None => {
                        let fault = self.faults[k];
                        target.set_invalid(fault.unwrap_or(ImageFault::Dropped), 0);
                        if fault.is_none() {
                            SensorCounters::add(&self.shared.sensors[k].sync_missed, 1);
                        }
                    }
                }
                self.faults[k] = None;
            }
            slot.frame.sequence = self.seq;
            slot.seq = self.seq;
            slot.arrived = first;
        }
        self.seq += 1;
        self.handover.post(self.shared, self.pool, h);
    }
}
