//! The pipeline's side of the iceoryx2 services ([`omnitrack_io::publish`]): opening a
//! publisher (a service that cannot be opened stops the run unless the caller allows running
//! without it), and marking the publish calls,
//! which allocate once per sample inside iceoryx2 0.10, for allocation counters
//! ([`inside_publish`]).
//!
//! In: a service name, or a publish call. Out: the publisher or why there is none; whether the
//! current thread is inside such a call.

use std::cell::Cell;

thread_local! {
    static IN_PUBLISH: Cell<bool> = const { Cell::new(false) };
}

/// Whether the current thread is inside an iceoryx2 publish call of the pipeline (which
/// allocates once per sample inside iceoryx2 0.10): for allocation counters. Never allocates.
pub fn inside_publish() -> bool {
    IN_PUBLISH.try_with(Cell::get).unwrap_or(false)
}

pub(super) fn publishing<T>(f: impl FnOnce() -> T) -> T {
    IN_PUBLISH.with(|c| c.set(true));
    let r = f();
    IN_PUBLISH.with(|c| c.set(false));
    r
}

pub(super) fn create_publisher<T: omnitrack_io::publish::Message>(
    service: Option<&str>,
    errors: &mut Option<String>,
) -> Option<omnitrack_io::publish::SamplePublisher<T>> {
    let service = service?;
    match omnitrack_io::publish::SamplePublisher::<T>::create(service) {
        Ok(p) => {
            if p.dead_nodes_cleaned() > 0 {
                tracing::info!(
                    service,
                    cleaned = p.dead_nodes_cleaned(),
                    "removed what crashed runs left"
                );
            }
            Some(p)
        }
        Err(e) => {
            tracing::debug!("cannot open the service: {e}");
            errors.get_or_insert_with(|| e.to_string());
            None
        }
    }
}
