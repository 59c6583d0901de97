//! The frame pool and the hand-over to the tracker: frame sets allocated at start-up, passed
//! between threads by index (a handle) through bounded crossbeam channels.
//!
//! In: a free handle, filled by capture or assembly. Out: the handle posted to the process
//! thread, where the latest frame wins (a pending one is replaced, counted as dropped and freed),
//! or, lossless, where capture waits.

use super::shared::{lock, Shared};
use super::TICK;
use crossbeam::channel::{bounded, Receiver, RecvTimeoutError, Select, SendTimeoutError, Sender, TrySendError};
use omnitrack_core::frame::FrameSet;
use omnitrack_core::rig::Rig;
use std::sync::atomic::Ordering;
use std::sync::{Mutex, MutexGuard};
use std::time::Instant;

/// A frame of the pool and what the pipeline knows of it.
pub(super) struct Slot {
    pub(super) frame: FrameSet,
    /// The pipeline's frame counter (gaps = dropped frames).
    pub(super) seq: u64,
    /// When it was handed into the pool.
    pub(super) arrived: Instant,
}

/// The preallocated frame sets and the list of free ones (handles = indices).
pub(super) struct Pool {
    slots: Box<[Mutex<Slot>]>,
    free_tx: Sender<usize>,
    pub(super) free_rx: Receiver<usize>,
}

impl Pool {
    pub(super) fn new(rig: &Rig, size: usize) -> Pool {
        let (free_tx, free_rx) = bounded(size);
        warm_channel(&free_tx, &free_rx, || 0);
        let now = Instant::now();
        let slots = (0..size)
            .map(|i| {
                free_tx.send(i).expect("room for every handle");
                Mutex::new(Slot {
                    frame: FrameSet::for_rig(rig),
                    seq: 0,
                    arrived: now,
                })
            })
            .collect();
        Pool {
            slots,
            free_tx,
            free_rx,
        }
    }

    pub(super) fn slot(&self, h: usize) -> MutexGuard<'_, Slot> {
        lock(&self.slots[h])
    }

    /// A free frame, waiting for one; `None` once the pipeline stops.
    pub(super) fn take(&self, shared: &Shared) -> Option<usize> {
        loop {
            if shared.stopping() {
                return None;
            }
            match self.free_rx.recv_timeout(TICK) {
                Ok(h) => return Some(h),
                Err(RecvTimeoutError::Timeout) => continue,
                Err(RecvTimeoutError::Disconnected) => return None,
            }
        }
    }

    pub(super) fn release(&self, h: usize) {
        // Never full: there are as many places as handles.
        let _ = self.free_tx.try_send(h);
    }
}

/// Takes, now, the memory a thread blocking on either side of the new, empty channel `tx`/`rx`
/// would take: crossbeam allocates a channel side's list of waiting threads the first time one
/// waits there, and a thread's wait context the first time it waits anywhere, so a first wait
/// falling late in a run (capture slower than the tracker for once, the sink stalled by the
/// disk, a search not done when due) allocated on the frame path (`tests/pipeline`). A waiter is
/// registered on each side and taken off at once (`Select::try_select`, which registers without
/// waiting): the list keeps its room, enough for four waiters. `fill` makes values to fill the
/// channel with so that a sender must wait; the channel is left empty. The calling thread's
/// context is made too.
pub(crate) fn warm_channel<T>(tx: &Sender<T>, rx: &Receiver<T>, mut fill: impl FnMut() -> T) {
    let mut waiting = Select::new();
    waiting.recv(rx);
    if let Ok(op) = waiting.try_select() {
        let _ = op.recv(rx);
    }
    while tx.try_send(fill()).is_ok() {}
    let mut waiting = Select::new();
    waiting.send(tx);
    if let Ok(op) = waiting.try_select() {
        let _ = op.send(tx, fill());
    }
    while rx.try_recv().is_ok() {}
}

/// The producer's side of the hand-over to the tracker: a channel of one handle, and a receiver
/// to take back a frame that a newer one replaces.
pub(super) struct Handover {
    pub(super) tx: Sender<usize>,
    pub(super) rx: Receiver<usize>,
}

impl Handover {
    /// Hands frame `h` to the tracker: the latest frame wins (or, lossless, waits). False once
    /// the pipeline stops (the frame is then counted as left, `Shared::leave`). Every frame
    /// posted is counted as captured, and ends processed, dropped or left.
    pub(super) fn post(&self, shared: &Shared, pool: &Pool, h: usize) -> bool {
        shared.frames_captured.fetch_add(1, Ordering::Relaxed);
        let mut h = h;
        if shared.lossless {
            loop {
                match self.tx.send_timeout(h, TICK) {
                    Ok(()) => return true,
                    Err(SendTimeoutError::Timeout(x)) => {
                        if shared.stopping() {
                            shared.leave(pool, x);
                            return false;
                        }
                        h = x;
                    }
                    Err(SendTimeoutError::Disconnected(x)) => {
                        shared.leave(pool, x);
                        return false;
                    }
                }
            }
        }
        loop {
            match self.tx.try_send(h) {
                Ok(()) => return true,
                Err(TrySendError::Full(x)) => {
                    h = x;
                    if let Ok(old) = self.rx.try_recv() {
                        self.drop_frame(shared, pool, old);
                    }
                }
                Err(TrySendError::Disconnected(x)) => {
                    shared.leave(pool, x);
                    return false;
                }
            }
        }
    }

    /// A frame replaced before the tracker took it: counted, back to the pool.
    fn drop_frame(&self, shared: &Shared, pool: &Pool, h: usize) {
        shared.give_back(pool, h, &shared.frames_dropped, |c| &c.overwritten);
    }
}
