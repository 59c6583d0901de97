//! The device runtime's log: `tracing` events to standard error, filtered by `OMNITRACK_LOG` or
//! `RUST_LOG`.
//!
//! In: those variables. Out: the global `tracing` subscriber, unless one is set already.

/// Installs the `tracing` subscriber of the device runtime unless one is set already: standard
/// error, `warn` and above by default; `OMNITRACK_LOG`, else `RUST_LOG`, raise or lower it with
/// `target=level` directives (`info`, `omnitrack=debug,iceoryx2=warn`). Returns whether it was
/// installed now.
pub fn init_logging() -> bool {
    use tracing_subscriber::filter::{LevelFilter, Targets};
    use tracing_subscriber::prelude::*;
    let spec = std::env::var("OMNITRACK_LOG")
        .ok()
        .filter(|s| !s.trim().is_empty())
        .or_else(|| std::env::var("RUST_LOG").ok().filter(|s| !s.trim().is_empty()));
    let default = Targets::new().with_default(LevelFilter::WARN);
    let (filter, bad) = match spec.as_deref().map(str::parse::<Targets>) {
        None => (default, None),
        Some(Ok(t)) => (t, None),
        Some(Err(e)) => (default, Some(e)),
    };
    let layer = tracing_subscriber::fmt::layer().with_writer(std::io::stderr);
    let installed = tracing_subscriber::registry()
        .with(layer)
        .with(filter)
        .try_init()
        .is_ok();
    if let (true, Some(e)) = (installed, bad) {
        tracing::warn!(
            "log filter {:?} not understood ({e}); logging warnings only",
            spec.unwrap_or_default()
        );
    }
    installed
}
