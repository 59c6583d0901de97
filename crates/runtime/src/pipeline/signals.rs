//! SIGINT and SIGTERM as a stop request: the first sets the pipeline's stop flag, a second one
//! while it is set exits at once with status 1.
//!
//! In: the stop flag. Out: a [`SignalGuard`]; while it lives the signals set the flag, after it
//! they terminate the process again.

use super::shared::lock;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// Signal handlers installed by [`stop_on_signals`]; dropping it removes them and gives SIGINT
/// and SIGTERM their default action (terminate) back.
#[derive(Debug)]
pub struct SignalGuard {
    ids: Vec<signal_hook::SigId>,
    default_action: Arc<AtomicBool>,
}

impl Drop for SignalGuard {
    fn drop(&mut self) {
        for id in self.ids.drain(..) {
            signal_hook::low_level::unregister(id);
        }
        self.default_action.store(true, Ordering::SeqCst);
    }
}

/// Makes SIGINT and SIGTERM set `stop` while the returned guard lives; a second one while `stop`
/// is already set exits the process at once with status 1 (a stuck shutdown can still be
/// interrupted). signal-hook cannot uninstall its handler, so the default action is emulated
/// after the guard is gone (one such emulation per process, off while a guard lives).
pub fn stop_on_signals(stop: &Arc<AtomicBool>) -> std::io::Result<SignalGuard> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    static DEFAULT_ACTION: Mutex<Option<Arc<AtomicBool>>> = Mutex::new(None);
    let default_action = {
        let mut d = lock(&DEFAULT_ACTION);
        match d.as_ref() {
            Some(flag) => Arc::clone(flag),
            None => {
                let flag = Arc::new(AtomicBool::new(false));
                for sig in [SIGINT, SIGTERM] {
                    signal_hook::flag::register_conditional_default(sig, Arc::clone(&flag))?;
                }
                *d = Some(Arc::clone(&flag));
                flag
            }
        }
    };
    default_action.store(false, Ordering::SeqCst);
    let mut guard = SignalGuard {
        ids: Vec::new(),
        default_action,
    };
    for sig in [SIGINT, SIGTERM] {
        // Registered first, so it sees the flag as it was before this signal.
        guard.ids.push(signal_hook::flag::register_conditional_shutdown(
            sig,
            1,
            Arc::clone(stop),
        )?);
        guard.ids.push(signal_hook::flag::register(sig, Arc::clone(stop))?);
    }
    Ok(guard)
}
