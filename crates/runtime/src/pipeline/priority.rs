//! Real-time scheduling of the frame path.
//!
//! In: `[budgets] realtime_priority` and the kind of pipeline thread starting. Out: that thread's
//! scheduling policy, and a [`Realtime`] outcome for the summary.
//!
//! Why: under the normal policy the kernel shares the cores fairly between runnable threads, so
//! two programs spinning beside the tracker on two cores take half the CPU from the frame path
//! whatever the tracker does, and a frame's latency stretches with them (p99 36–54 ms beside two
//! CPU hogs against 17–28 ms idle). A frame path at `SCHED_FIFO` runs as soon as its input is
//! there and until it blocks, so other programs get the time between frames instead of the time
//! inside them. The searches (initialisation, relocalisation) stay at the normal policy: they are
//! minutes of work in the worst case, must not starve the rest of the machine, and their answers
//! do not depend on the time they get (their budgets count work).
//!
//! Which threads: capture, assembly and process are set here as they start, capture and assembly
//! one priority below the rest (a frame being tracked goes first: with equal priorities the
//! replay's capture, decoding the next frame's six PNGs, held the edge stage of the current one
//! until it was done); the edge detector's
//! workers are started by the process thread after it was set, and a new thread inherits its
//! creator's policy (Linux `clone`); the search thread, also started by the process thread, is
//! put back to the normal policy, and the whole-model search's lanes inherit that.
//!
//! Only where frames come in real time (latest frame wins): a lossless run (an offline replay as
//! fast as it decodes) keeps the frame path busy without a pause, and at `SCHED_FIFO` would leave
//! the rest of the machine the kernel's throttling margin alone; it has no latency to protect.
//!
//! The OS may refuse: `SCHED_FIFO` needs root, `CAP_SYS_NICE` or an `RLIMIT_RTPRIO` of at least
//! the priority (systemd: `LimitRTPRIO=`). A refusal is one warning and the run goes on at the
//! normal policy; the summary says which ([`Realtime`]).

use super::PipelineThread;

/// What the frame path's threads got.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Realtime {
    /// `realtime_priority = 0`: every thread at the normal policy.
    Off,
    /// A lossless run (an offline replay): no latency to protect, and a frame path kept busy
    /// without a pause would leave other programs only the kernel's real-time throttling margin
    /// (5 %); every thread at the normal policy.
    Lossless,
    /// Every frame-path thread that started runs at `SCHED_FIFO` with this priority.
    Granted(u8),
    /// The OS refused it for at least one frame-path thread, which runs at the normal policy.
    Refused { priority: u8, reason: String },
}

impl std::fmt::Display for Realtime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Realtime::Off => write!(f, "normal scheduling (realtime_priority = 0)"),
            Realtime::Lossless => write!(f, "normal scheduling (a lossless run)"),
            Realtime::Granted(p) => write!(f, "frame path at SCHED_FIFO {p} (capture {})", upstream_priority(*p)),
            Realtime::Refused { priority, reason } => {
                write!(
                    f,
                    "frame path at normal scheduling: SCHED_FIFO {priority} refused ({reason})"
                )
            }
        }
    }
}

/// Sets the calling thread's policy for its role. `Ok(true)`: set to `SCHED_FIFO priority`;
/// `Ok(false)`: nothing to do (off, or a thread that stays normal); `Err`: the OS's reason.
pub(super) fn apply(thread: PipelineThread, priority: u8) -> Result<bool, String> {
    if priority == 0 {
        return Ok(false);
    }
    match thread {
        PipelineThread::Process => set_current(Some(priority)).map(|()| true),
        // One below: a frame being tracked goes before the next one being read in.
        PipelineThread::Capture { .. } | PipelineThread::Assembly => {
            set_current(Some(upstream_priority(priority))).map(|()| true)
        }
        // Inherited from the process thread that started it: back to normal.
        PipelineThread::Search => set_current(None).map(|()| false),
        // The caller's own thread: not ours to change.
        PipelineThread::Sink => Ok(false),
    }
}

/// The priority of capture and assembly for a frame path at `priority`.
pub fn upstream_priority(priority: u8) -> u8 {
    priority.saturating_sub(1).max(1)
}

/// `Some(p)`: `SCHED_FIFO` at p; `None`: the normal policy.
#[cfg(unix)]
fn set_current(priority: Option<u8>) -> Result<(), String> {
    let (policy, p) = match priority {
        Some(p) => (libc::SCHED_FIFO, i32::from(p)),
        None => (libc::SCHED_OTHER, 0),
    };
    let param = libc::sched_param { sched_priority: p };
    // SAFETY: `pthread_self` is always valid for the calling thread and `param` outlives the call.
    let rc = unsafe { libc::pthread_setschedparam(libc::pthread_self(), policy, &param) };
    if rc == 0 {
        Ok(())
    } else {
        let e = std::io::Error::from_raw_os_error(rc);
        Err(match rc {
            libc::EPERM => format!("{e}; needs root, CAP_SYS_NICE or RLIMIT_RTPRIO >= {p}"),
            _ => e.to_string(),
        })
    }
}

#[cfg(not(unix))]
fn set_current(priority: Option<u8>) -> Result<(), String> {
    match priority {
        Some(_) => Err("not supported on this platform".into()),
        None => Ok(()),
    }
}

/// A thread's scheduling as the OS reports it ([`current_thread_policy`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ThreadPolicy {
    /// Whether the policy is `SCHED_FIFO`.
    pub fifo: bool,
    /// Its static priority (0 under the normal policy).
    pub priority: i32,
}

impl ThreadPolicy {
    /// The normal policy (`SCHED_OTHER`, priority 0).
    pub const NORMAL: ThreadPolicy = ThreadPolicy {
        fifo: false,
        priority: 0,
    };

    /// `SCHED_FIFO` at `priority`.
    pub const fn fifo(priority: i32) -> ThreadPolicy {
        ThreadPolicy { fifo: true, priority }
    }
}

/// The calling thread's policy and priority as the OS reports them (the normal policy when it
/// cannot tell).
#[cfg(unix)]
pub fn current_thread_policy() -> ThreadPolicy {
    let mut policy = 0;
    let mut param = libc::sched_param { sched_priority: 0 };
    // SAFETY: both out-pointers are valid for the call.
    let rc = unsafe { libc::pthread_getschedparam(libc::pthread_self(), &mut policy, &mut param) };
    if rc != 0 {
        return ThreadPolicy::NORMAL;
    }
    ThreadPolicy {
        fifo: policy == libc::SCHED_FIFO,
        priority: param.sched_priority,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_search_and_the_sink_never_become_realtime() {
        std::thread::spawn(|| {
            assert_eq!(apply(PipelineThread::Search, 10), Ok(false));
            assert_eq!(apply(PipelineThread::Sink, 10), Ok(false));
            assert_eq!(current_thread_policy(), ThreadPolicy::NORMAL);
            assert_eq!(apply(PipelineThread::Process, 0), Ok(false));
            assert_eq!(current_thread_policy(), ThreadPolicy::NORMAL);
        })
        .join()
        .unwrap();
    }

    #[test]
    fn a_frame_path_thread_gets_fifo_or_a_reason_and_its_children_inherit_it() {
        std::thread::spawn(|| match apply(PipelineThread::Process, 7) {
            Ok(set) => {
                assert!(set);
                assert_eq!(current_thread_policy(), ThreadPolicy::fifo(7));
                // An edge worker started now inherits it; the search thread puts itself back.
                let child = std::thread::spawn(current_thread_policy).join().unwrap();
                assert_eq!(child, ThreadPolicy::fifo(7));
                let search = std::thread::spawn(|| {
                    apply(PipelineThread::Search, 7).unwrap();
                    current_thread_policy()
                })
                .join()
                .unwrap();
                assert_eq!(search, ThreadPolicy::NORMAL);
            }
            Err(reason) => {
                assert!(!reason.is_empty());
                assert_eq!(current_thread_policy(), ThreadPolicy::NORMAL);
            }
        })
        .join()
        .unwrap();
    }
}
