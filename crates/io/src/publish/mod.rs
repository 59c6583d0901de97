//! Poses out to other processes on the same computer over iceoryx2 zero-copy shared memory.
//!
//! In: a [`PoseSample`] per frame (built from the tracker's `T_world_rig`, its covariance and
//! counters with [`PoseSample::from_pose`]) and now and then a [`StatusSample`]. Out: the
//! publish–subscribe services `omnitrack/pose` and `omnitrack/status` (docs/interfaces.md, "Pose
//! service"). The publisher knows the pose message only: nothing of frames, edges or the tracker.
//!
//! Each service keeps a history of one sample, so a subscriber that starts late gets the latest
//! pose at once (on the publisher's next publish or `update_connections`, see below); each
//! subscriber has a buffer of [`SUBSCRIBER_BUFFER`] samples and on overflow the oldest is
//! replaced (a slow reader sees the newest poses, the tracker never blocks). Beside each
//! publish–subscribe service is an event service of the same name: the publisher notifies it
//! after every send so that a subscriber can sleep until a sample arrives
//! ([`SampleSubscriber::wait`]) instead of polling.
//!
//! The sample is loaned from the shared-memory pool preallocated at [`SamplePublisher::create`],
//! written in place and sent. One heap allocation per publish remains, inside iceoryx2 0.10: the
//! loan wraps the chunk's bookkeeping in a small `Arc` (`ChunkMutSharedState::new`), freed at
//! send; the public API has no way around it (`send_copy` loans the same way). Receiving,
//! notifying and [`SamplePublisher::update_connections`] allocate nothing. `tests/publish.rs`
//! counts both so that any further allocation is caught.
//!
//! History is handed to a late subscriber by the publisher when it next updates its connections:
//! on every publish, or on [`SamplePublisher::update_connections`], which a publisher that has
//! nothing to send for a while should call now and then.
//!
//! Who may reach the services: before a node is made, iceoryx2's folders and node counter file are
//! checked and made group-only where missing, a file of another user is refused in one line, a
//! damaged counter is repaired; omnitrack's nodes count in a counter file of their own; after the
//! ports are made, every file the process owns in the domain is given to the domain's group
//! (`domain.rs`; README, "Who can subscribe to poses"). Service names, iceoryx2's root folder and
//! prefix stay its defaults, so a default-config consumer finds the services.
//!
//! Creating a publisher or subscriber first removes what crashed earlier runs left in `/dev/shm`
//! (dead nodes and their ports), and sets iceoryx2's log level to `Error` unless `IOX2_LOG_LEVEL`
//! says otherwise (so no process warns about the optional config file). The ports use
//! `ipc_threadsafe` services: a publisher may be created on one thread and moved to another.
//! No signal handlers are installed: Ctrl-C ends a process as usual, and the next start cleans up.

mod domain;
mod listen;
mod sample;

use std::fmt::Debug;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Once};
use std::time::{Duration, Instant};

use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::{
    ipc_threadsafe, set_log_level_from_env_or, LogLevel, Node, NodeBuilder, NodeName, ServiceName, SignalHandlingMode,
    ZeroCopySend,
};
use iceoryx2::service::port_factory::{event as event_factory, publish_subscribe as pubsub_factory};

use domain::Domain;

pub use domain::{COUNTER_SUFFIX, SHM_DIR};
pub use listen::{
    format_pose_line, format_status_line, listen, listen_as, listen_status, listen_status_as, ListenError,
};
pub use sample::{
    PoseSample, SearchKind, SearchState, Stage, StatusSample, TrackerState, WireError, POSE_WIRE_BYTES,
    STATUS_MAX_SENSORS, STATUS_SOURCE_BYTES, STATUS_STAGES,
};

/// Name of the pose service (docs/interfaces.md).
pub const POSE_SERVICE: &str = "omnitrack/pose";
/// Name of the status service.
pub const STATUS_SERVICE: &str = "omnitrack/status";
/// Samples a late subscriber receives at once: the latest one.
pub const HISTORY_SIZE: usize = 1;
/// Samples buffered per subscriber before the oldest is overwritten (≈ 0.25 s at 30 Hz).
pub const SUBSCRIBER_BUFFER: usize = 8;
/// Subscribers a service accepts at once.
pub const MAX_SUBSCRIBERS: usize = 16;
/// Publishers a service accepts at once (one tracker, plus one spare for a hand-over).
pub const MAX_PUBLISHERS: usize = 2;

/// The iceoryx2 service flavour used for all ports: inter-process, ports are `Send`.
pub type Ipc = ipc_threadsafe::Service;

/// A message that can go through [`SamplePublisher`] / [`SampleSubscriber`]: plain `#[repr(C)]`
/// data with a stable iceoryx2 type name.
pub trait Message: Debug + Copy + ZeroCopySend + 'static {}
impl Message for PoseSample {}
impl Message for StatusSample {}

/// What went wrong talking to iceoryx2, with the step and the service it was for.
#[derive(Debug, thiserror::Error)]
#[error("iceoryx2: {step} for service '{service}': {detail}")]
pub struct PublishError {
    /// The step that failed (e.g. "create node", "open service", "send").
    pub step: &'static str,
    /// The service name.
    pub service: String,
    /// iceoryx2's error.
    pub detail: String,
}

impl PublishError {
    fn new(step: &'static str, service: &str, detail: impl Debug) -> Self {
        PublishError {
            step,
            service: service.to_string(),
            detail: format!("{detail:?}"),
        }
    }

    /// A refusal of the domain's files ([`domain`]): already one line that says what to do.
    fn files(service: &str, detail: String) -> Self {
        PublishError {
            step: "shared-memory files",
            service: service.to_string(),
            detail,
        }
    }

    /// iceoryx2's error, with the files of other users that may be the cause.
    fn in_domain(step: &'static str, service: &str, detail: impl Debug, domain: &Domain) -> Self {
        PublishError {
            step,
            service: service.to_string(),
            detail: format!("{detail:?}{}", domain.foreign_files()),
        }
    }
}

/// The stop flag of a subscriber process (`omnitrack-link`, `omnitrack-ros2`): set by SIGINT
/// or SIGTERM, whose first arrival cuts a [`PoseSubscriber::wait`] short; the second of either
/// ends the process at once. The device pipeline has its own, which it can undo
/// (`omnitrack_runtime::pipeline::stop_on_signals`).
pub fn stop_on_signals() -> Arc<AtomicBool> {
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        let _ = signal_hook::flag::register_conditional_shutdown(signal, 1, Arc::clone(&stop));
        let _ = signal_hook::flag::register(signal, Arc::clone(&stop));
    }
    stop
}

static LOG_LEVEL: Once = Once::new();

/// Sets iceoryx2's log level once per process: `IOX2_LOG_LEVEL` if set, else `Error`. Called by
/// every constructor here; call it yourself before using iceoryx2 directly.
pub fn quiet_iceoryx2_logs() {
    LOG_LEVEL.call_once(|| set_log_level_from_env_or(LogLevel::Error));
}

/// Checks the domain's files ([`Domain::prepare`]), creates a node (no signal handlers) that counts
/// in omnitrack's own node counter file, and removes the resources of dead nodes (crashed earlier
/// runs). Returns the node, how many dead nodes were cleaned, and the domain.
fn create_node(name: &str, service: &str) -> Result<(Node<Ipc>, u64, Domain), PublishError> {
    quiet_iceoryx2_logs();
    let domain = Domain::prepare().map_err(|e| PublishError::files(service, e))?;
    let node_name = NodeName::new(name).map_err(|e| PublishError::new("node name", service, e))?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .config(domain.node_config())
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Ipc>()
        .map_err(|e| PublishError::in_domain("create node", service, e, &domain))?;
    let cleaned = node.try_cleanup_dead_nodes();
    Ok((node, cleaned.cleanups, domain))
}

/// Retries `open` while iceoryx2 reports missing permissions, for at most a second: a file
/// another process of the group has just made is owner-only until that process shares it
/// ([`Domain::share_with_group`]), a few milliseconds later.
fn retry_permissions<T, E: Debug>(mut open: impl FnMut() -> Result<T, E>) -> Result<T, E> {
    let deadline = Instant::now() + Duration::from_secs(1);
    loop {
        match open() {
            Err(e) if format!("{e:?}").contains("InsufficientPermissions") && Instant::now() < deadline => {
                std::thread::sleep(Duration::from_millis(10));
            }
            other => return other,
        }
    }
}

fn service_name(service: &str) -> Result<ServiceName, PublishError> {
    ServiceName::new(service).map_err(|e| PublishError::new("service name", service, e))
}

fn open_pubsub<T: Message>(
    node: &Node<Ipc>,
    service: &str,
    domain: &Domain,
) -> Result<pubsub_factory::PortFactory<Ipc, T, ()>, PublishError> {
    let name = service_name(service)?;
    retry_permissions(|| {
        node.service_builder(&name)
            .publish_subscribe::<T>()
            .history_size(HISTORY_SIZE)
            .subscriber_max_buffer_size(SUBSCRIBER_BUFFER)
            .enable_safe_overflow(true)
            .max_subscribers(MAX_SUBSCRIBERS)
            .max_publishers(MAX_PUBLISHERS)
            .open_or_create()
    })
    .map_err(|e| PublishError::in_domain("open or create publish-subscribe service", service, e, domain))
}

fn open_event(
    node: &Node<Ipc>,
    service: &str,
    domain: &Domain,
) -> Result<event_factory::PortFactory<Ipc>, PublishError> {
    let name = service_name(service)?;
    retry_permissions(|| node.service_builder(&name).event().open_or_create())
        .map_err(|e| PublishError::in_domain("open or create event service", service, e, domain))
}

/// Publishes samples of one message type on one service. Create once at start-up; every
/// [`publish`](Self::publish) after that is allocation-free.
pub struct SamplePublisher<T: Message> {
    // Field order is drop order: ports before their services, services before the node.
    publisher: Publisher<Ipc, T, ()>,
    notifier: Notifier<Ipc>,
    _service: pubsub_factory::PortFactory<Ipc, T, ()>,
    _events: event_factory::PortFactory<Ipc>,
    _node: Node<Ipc>,
    service: String,
    dead_nodes_cleaned: u64,
}

/// Publisher of [`PoseSample`]s (service [`POSE_SERVICE`] in production).
pub type PosePublisher = SamplePublisher<PoseSample>;
/// Publisher of [`StatusSample`]s (service [`STATUS_SERVICE`] in production).
pub type StatusPublisher = SamplePublisher<StatusSample>;

impl<T: Message> SamplePublisher<T> {
    /// Opens (or creates) `service` with history 1, a subscriber buffer of [`SUBSCRIBER_BUFFER`]
    /// and overflow on, plus its event service, and creates the publisher and notifier ports.
    pub fn create(service: &str) -> Result<Self, PublishError> {
        let (node, dead_nodes_cleaned, domain) = create_node("omnitrack-publisher", service)?;
        let pubsub = open_pubsub::<T>(&node, service, &domain)?;
        // One tracker per service: a second one would interleave its poses with the first's and
        // nothing in a sample tells them apart. (Publishers of crashed runs were cleaned above.)
        let others = iceoryx2::service::port_factory::PortFactory::dynamic_config(&pubsub).number_of_publishers();
        if others > 0 {
            return Err(PublishError::new(
                "create publisher",
                service,
                format_args!("another process publishes on it ({others}): one tracker per service"),
            ));
        }
        let events = open_event(&node, service, &domain)?;
        let publisher = pubsub
            .publisher_builder()
            .max_loaned_samples(1)
            .create()
            .map_err(|e| PublishError::new("create publisher", service, e))?;
        let notifier = events
            .notifier_builder()
            .create()
            .map_err(|e| PublishError::new("create notifier", service, e))?;
        domain.share_with_group().map_err(|e| PublishError::files(service, e))?;
        Ok(SamplePublisher {
            publisher,
            notifier,
            _service: pubsub,
            _events: events,
            _node: node,
            service: service.to_string(),
            dead_nodes_cleaned,
        })
    }

    /// Loans a sample from shared memory, writes `value` into it, sends it to every subscriber
    /// and wakes those waiting on the event service. Returns the number of subscribers reached.
    pub fn publish(&self, value: &T) -> Result<usize, PublishError> {
        let sample = self
            .publisher
            .loan_uninit()
            .map_err(|e| PublishError::new("loan", &self.service, e))?;
        let sample = sample.write_payload(*value);
        let reached = sample.send().map_err(|e| PublishError::new("send", &self.service, e))?;
        self.notifier
            .notify()
            .map_err(|e| PublishError::new("notify", &self.service, e))?;
        Ok(reached)
    }

    /// Connects subscribers that appeared since the last publish and hands each the history
    /// sample (the latest one). Every [`publish`](Self::publish) does this first; call it when no
    /// sample is due for a while (e.g. while initialising, every 100 ms) so a late subscriber gets
    /// the latest sample without waiting for the next publish. Allocation-free.
    pub fn update_connections(&self) -> Result<(), PublishError> {
        self.publisher
            .update_connections()
            .map_err(|e| PublishError::new("update connections", &self.service, e))
    }

    /// The service name this publisher sends on.
    pub fn service(&self) -> &str {
        &self.service
    }

    /// How many dead nodes (crashed earlier runs) were cleaned up when this publisher was created.
    pub fn dead_nodes_cleaned(&self) -> u64 {
        self.dead_nodes_cleaned
    }
}

impl PosePublisher {
    /// Builds a [`PoseSample`] with [`PoseSample::from_pose`] and publishes it.
    #[allow(clippy::too_many_arguments)]
    pub fn publish_pose(
        &self,
        timestamp_ns: u64,
        sequence: u64,
        status: TrackerState,
        pose: &omnitrack_core::geometry::Pose,
        covariance: &nalgebra::Matrix6<f64>,
        inliers: u32,
        xi_rad2: f64,
    ) -> Result<usize, PublishError> {
        self.publish(&PoseSample::from_pose(
            timestamp_ns,
            sequence,
            status,
            pose,
            covariance,
            inliers,
            xi_rad2,
        ))
    }
}

/// Receives samples of one message type from one service, by polling or by waiting on the
/// service's event (the publisher notifies after each send).
pub struct SampleSubscriber<T: Message> {
    subscriber: Subscriber<Ipc, T, ()>,
    listener: Listener<Ipc>,
    _service: pubsub_factory::PortFactory<Ipc, T, ()>,
    _events: event_factory::PortFactory<Ipc>,
    _node: Node<Ipc>,
    service: String,
}

/// Subscriber of [`PoseSample`]s.
pub type PoseSubscriber = SampleSubscriber<PoseSample>;
/// Subscriber of [`StatusSample`]s.
pub type StatusSubscriber = SampleSubscriber<StatusSample>;

impl<T: Message> SampleSubscriber<T> {
    /// Opens (or creates, so that a subscriber may start before the tracker) `service` with the
    /// same settings as the publisher, and creates the subscriber and listener ports. If the
    /// service already holds a sample, the first [`receive`](Self::receive) returns it.
    pub fn create(service: &str) -> Result<Self, PublishError> {
        let (node, _, domain) = create_node("omnitrack-subscriber", service)?;
        let pubsub = open_pubsub::<T>(&node, service, &domain)?;
        let events = open_event(&node, service, &domain)?;
        let subscriber = pubsub
            .subscriber_builder()
            .buffer_size(SUBSCRIBER_BUFFER)
            .create()
            .map_err(|e| PublishError::new("create subscriber", service, e))?;
        let listener = events
            .listener_builder()
            .create()
            .map_err(|e| PublishError::new("create listener", service, e))?;
        domain.share_with_group().map_err(|e| PublishError::files(service, e))?;
        // A tracker of another user that met the listener in the instant before it was shared
        // could not connect (its notifier, unlike its publisher, does not wait for a file's
        // rights) and would not try again until the listeners change: a listener made and
        // dropped here changes them, so it connects to this one too.
        drop(events.listener_builder().create());
        Ok(SampleSubscriber {
            subscriber,
            listener,
            _service: pubsub,
            _events: events,
            _node: node,
            service: service.to_string(),
        })
    }

    /// The oldest buffered sample, copied out of shared memory, or `None` when there is none.
    /// Never blocks.
    pub fn receive(&self) -> Result<Option<T>, PublishError> {
        match self.subscriber.receive() {
            Ok(Some(sample)) => Ok(Some(*sample.payload())),
            Ok(None) => Ok(None),
            Err(e) => Err(PublishError::new("receive", &self.service, e)),
        }
    }

    /// Waits at most `timeout` for a sample, sleeping on the event service between checks;
    /// `None` when none came in time, or when a signal interrupted the sleep.
    pub fn wait(&self, timeout: Duration) -> Result<Option<T>, PublishError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(s) = self.receive()? {
                return Ok(Some(s));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            // A notification may have been consumed earlier without its sample being taken (or a
            // sample may arrive from a publisher that does not notify): never sleep longer than
            // a short slice, so the wait stays bounded and still sees such samples.
            let slice = (deadline - now).min(Duration::from_millis(50));
            match self.listener.timed_wait(|_| {}, slice) {
                Ok(_) => {}
                // A signal (SIGINT, SIGTERM) cut the sleep short: that is no fault of the
                // service, and the caller's stop flag says whether to go on. As an error it
                // ended `omnitrack-link send` with exit 1 on every SIGTERM.
                Err(ListenerWaitError::InterruptSignal) => return Ok(None),
                Err(e) => return Err(PublishError::new("wait on event", &self.service, e)),
            }
        }
    }

    /// Polls for a sample until `timeout`: spins (with `yield`) rather than sleeping; lowest
    /// latency, one busy core.
    pub fn poll(&self, timeout: Duration) -> Result<Option<T>, PublishError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(s) = self.receive()? {
                return Ok(Some(s));
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            std::thread::yield_now();
        }
    }

    /// The service name this subscriber listens on.
    pub fn service(&self) -> &str {
        &self.service
    }
}
