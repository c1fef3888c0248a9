//! The IPC contract of the CRS control stack: every process (motion-core, drive-io, sim-plant,
//! safety-monitor, tools) exchanges data only through the services and payloads defined here.
//!
//! * Payloads are `#[repr(C)]`, `Copy`, heap-free and carry [`CONTRACT_VERSION`]; their iceoryx2
//!   type names include the version, so a process built against another contract version cannot
//!   open the service (iceoryx2 rejects the type mismatch) instead of misreading memory.
//! * Service names live in [`topics`]; each [`Topic`] fixes its subscriber buffer, history and
//!   port counts in ONE place, so every process opens the service with identical settings
//!   (iceoryx2 refuses to open a service with incompatible settings).
//! * Buffers are sized deliberately: iceoryx2 0.10's default subscriber buffer of 2 with safe
//!   overflow silently drops samples for a reader slower than the writer (a 15 ms safety monitor
//!   reading a 1 kHz stream would lose 13 of 15 setpoints).
//! * No event notifications in the 1 ms hard loop: `notify()` costs the publisher 10-30 us (a
//!   syscall). Cyclic readers poll. Two event services: [`IpcNode::wakeup_notifier`] for rare
//!   events (e-stop), and [`IpcNode::setpoint_ready_notifier`], notified by motion-core's publish
//!   stage (a thread beside the hard loop) so drive-io's SYNC follows the setpoint within the
//!   same period.
//! * [`IpcNode::new`] passes an explicit iceoryx2 [`Config`] (no "no config file" warning) and
//!   removes stale resources of dead nodes before creating its own node.
//! * Tests isolate themselves with a service-name prefix: [`IpcNode::with_prefix`] or the
//!   `CRS_IPC_PREFIX` environment variable read by [`IpcNode::new`].

mod codes;
pub mod identity_golden;
mod payloads;
pub mod ride_control;
pub mod topics;

pub use codes::{
    FaultCode, MonitorCode, MonitorState, MotionState, PLAN_OPEN_END, PlantState, TripCause,
    UnknownCode,
};
pub use payloads::*;
pub use topics::Topic;

use iceoryx2::node::NodeView;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{
    CallbackProgression, Config, Node, NodeBuilder, NodeName, NodeState, ServiceName,
    SignalHandlingMode, ipc,
};
use std::time::Duration;

/// Environment variable holding a service-name prefix (e.g. a per-test unique string).
pub const PREFIX_ENV: &str = "CRS_IPC_PREFIX";

/// Errors of the IPC layer. Carries the service name so a failure says which contract part broke.
#[derive(Debug, thiserror::Error)]
pub enum IpcError {
    #[error("invalid iceoryx2 name {name:?}: {detail}")]
    InvalidName { name: String, detail: String },
    #[error("creating iceoryx2 node {node:?} failed: {detail}")]
    Node { node: String, detail: String },
    #[error("service {service:?}: {op} failed: {detail}")]
    Service {
        service: String,
        op: &'static str,
        detail: String,
    },
    #[error("service {service:?}: payload version {found} != contract version {expected}")]
    Version {
        service: String,
        found: u32,
        expected: u32,
    },
}

fn svc_err(service: &str, op: &'static str, e: impl core::fmt::Debug) -> IpcError {
    IpcError::Service {
        service: service.to_string(),
        op,
        detail: format!("{e:?}"),
    }
}

/// The stack's one clock (CLOCK_MONOTONIC ns, defined in crs-rt): the time base of every
/// `*_ns` payload field, shared by all processes on one host.
pub use crs_rt::monotonic_ns;

/// The iceoryx2 configuration all CRS processes use (defaults, passed explicitly).
pub fn iceoryx_config() -> Config {
    Config::default()
}

/// Removes the shared-memory resources of nodes whose process died (e.g. after `kill -9`).
/// Returns how many dead nodes were cleaned up.
pub fn cleanup_dead_nodes(config: &Config) -> usize {
    let mut removed = 0;
    let _ = Node::<ipc::Service>::list(config, |state| {
        if let NodeState::Dead(view) = state {
            tracing::warn!(node = ?view.id(), "removing stale resources of a dead iceoryx2 node");
            if view.try_remove_stale_resources().is_ok() {
                removed += 1;
            }
        }
        CallbackProgression::Continue
    });
    removed
}

/// One process's connection to the process bus.
pub struct IpcNode {
    node: Node<ipc::Service>,
    prefix: String,
}

impl IpcNode {
    /// Creates a node named `node_name`; the service prefix comes from `CRS_IPC_PREFIX` (empty if unset).
    pub fn new(node_name: &str) -> Result<Self, IpcError> {
        let prefix = std::env::var(PREFIX_ENV).unwrap_or_default();
        Self::with_prefix(node_name, &prefix)
    }

    /// Creates a node whose services are all named `<prefix><topic name>`.
    pub fn with_prefix(node_name: &str, prefix: &str) -> Result<Self, IpcError> {
        let config = iceoryx_config();
        cleanup_dead_nodes(&config);
        let name: NodeName = node_name.try_into().map_err(|e| IpcError::InvalidName {
            name: node_name.to_string(),
            detail: format!("{e:?}"),
        })?;
        let node = NodeBuilder::new()
            .name(&name)
            // Daemons install their own signal handling; iceoryx2 must not swallow SIGINT/SIGTERM.
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .config(&config)
            .create::<ipc::Service>()
            .map_err(|e| IpcError::Node {
                node: node_name.to_string(),
                detail: format!("{e:?}"),
            })?;
        Ok(Self {
            node,
            prefix: prefix.to_string(),
        })
    }

    /// The full service name of topic `T` for this node's prefix.
    pub fn service_name<T: Topic>(&self) -> String {
        format!("{}{}", self.prefix, T::NAME)
    }

    fn open_service<T: Topic>(
        &self,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>,
        IpcError,
    > {
        let full = self.service_name::<T>();
        let sname: ServiceName = full
            .as_str()
            .try_into()
            .map_err(|e| IpcError::InvalidName {
                name: full.clone(),
                detail: format!("{e:?}"),
            })?;
        self.node
            .service_builder(&sname)
            .publish_subscribe::<T>()
            .history_size(T::HISTORY)
            .subscriber_max_buffer_size(T::SUBSCRIBER_BUFFER)
            .max_publishers(T::MAX_PUBLISHERS)
            .max_subscribers(T::MAX_SUBSCRIBERS)
            .max_nodes(T::MAX_NODES)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(|e| svc_err(&full, "open_or_create", e))
    }

    /// Opens a typed publisher for topic `T` with the contract's settings.
    pub fn publisher<T: Topic>(&self) -> Result<TopicPublisher<T>, IpcError> {
        let service = self.service_name::<T>();
        let port = self
            .open_service::<T>()?
            .publisher_builder()
            .create()
            .map_err(|e| svc_err(&service, "create publisher", e))?;
        Ok(TopicPublisher { port, service })
    }

    /// Opens a typed subscriber for topic `T` with the contract's buffer size.
    pub fn subscriber<T: Topic>(&self) -> Result<TopicSubscriber<T>, IpcError> {
        let service = self.service_name::<T>();
        let factory = self.open_service::<T>()?;
        let port = factory
            .subscriber_builder()
            .buffer_size(T::SUBSCRIBER_BUFFER)
            .create()
            .map_err(|e| svc_err(&service, "create subscriber", e))?;
        Ok(TopicSubscriber {
            port,
            service,
            factory,
        })
    }

    fn notifier_port(&self, name: &str) -> Result<(Notifier<ipc::Service>, String), IpcError> {
        let (service, f) = self.event_service(name)?;
        let port = f
            .notifier_builder()
            .create()
            .map_err(|e| svc_err(&service, "create notifier", e))?;
        Ok((port, service))
    }

    fn listener_port(&self, name: &str) -> Result<(Listener<ipc::Service>, String), IpcError> {
        let (service, f) = self.event_service(name)?;
        let port = f
            .listener_builder()
            .create()
            .map_err(|e| svc_err(&service, "create listener", e))?;
        Ok((port, service))
    }

    fn event_service(
        &self,
        name: &str,
    ) -> Result<
        (
            String,
            iceoryx2::service::port_factory::event::PortFactory<ipc::Service>,
        ),
        IpcError,
    > {
        let full = format!("{}{}", self.prefix, name);
        let sname: ServiceName = full
            .as_str()
            .try_into()
            .map_err(|e| IpcError::InvalidName {
                name: full.clone(),
                detail: format!("{e:?}"),
            })?;
        let f = self
            .node
            .service_builder(&sname)
            .event()
            .open_or_create()
            .map_err(|e| svc_err(&full, "open_or_create event", e))?;
        Ok((full, f))
    }

    /// Notifier for the rare-event wake-up service (`crs/v1/wakeup`): call it after publishing an
    /// e-stop [`StateEvent`], never in a 1 ms loop (10-30 us per notify).
    pub fn wakeup_notifier(&self) -> Result<WakeupNotifier, IpcError> {
        let (port, service) = self.notifier_port(topics::WAKEUP_EVENT)?;
        Ok(WakeupNotifier { port, service })
    }

    /// Listener for the wake-up service, for processes that sleep until an event arrives.
    pub fn wakeup_listener(&self) -> Result<WakeupListener, IpcError> {
        let (port, service) = self.listener_port(topics::WAKEUP_EVENT)?;
        Ok(WakeupListener { port, service })
    }

    /// Notifier of [`topics::SETPOINT_READY_EVENT`], for the process that publishes
    /// [`JointSetpoint`]s (motion-core's publish stage): notify after publishing.
    pub fn setpoint_ready_notifier(&self) -> Result<WakeupNotifier, IpcError> {
        let (port, service) = self.notifier_port(topics::SETPOINT_READY_EVENT)?;
        Ok(WakeupNotifier { port, service })
    }

    /// Listener of [`topics::SETPOINT_READY_EVENT`] (drive-io): its file descriptor goes into
    /// the same ppoll as the CAN socket ([`SetpointReadyListener::raw_fd`]).
    pub fn setpoint_ready_listener(&self) -> Result<SetpointReadyListener, IpcError> {
        let (port, service) = self.listener_port(topics::SETPOINT_READY_EVENT)?;
        Ok(SetpointReadyListener { port, service })
    }
}

/// Typed publisher: copies a payload into shared memory and sends it (no heap allocation).
pub struct TopicPublisher<T: Topic> {
    port: Publisher<ipc::Service, T, ()>,
    service: String,
}

impl<T: Topic> TopicPublisher<T> {
    /// Publishes a copy of `value`. The error path allocates (formats the message); the good path does not.
    pub fn publish(&self, value: &T) -> Result<(), IpcError> {
        let sample = self
            .port
            .loan_uninit()
            .map_err(|e| svc_err(&self.service, "loan", e))?;
        sample
            .write_payload(*value)
            .send()
            .map_err(|e| svc_err(&self.service, "send", e))?;
        Ok(())
    }
    pub fn service_name(&self) -> &str {
        &self.service
    }
}

/// Typed subscriber with payload-version checking.
pub struct TopicSubscriber<T: Topic> {
    port: Subscriber<ipc::Service, T, ()>,
    service: String,
    /// The service, kept for introspection of its publishers ([`TopicSubscriber::publishers`]).
    factory: iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>,
}

/// One publisher of a service as iceoryx2 0.10's dynamic service configuration lists it: the
/// process id encoded in its node's unique id (`UniqueNodeId::pid`), None if it cannot be
/// read. iceoryx2 does not authenticate it further; see docs/safety-monitor.md (threat model).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PublisherInfo {
    pub pid: Option<i32>,
}

impl<T: Topic> TopicSubscriber<T> {
    /// Next buffered sample (copied out), `Ok(None)` if the buffer is empty. A sample with a
    /// foreign contract version is an error (and consumed).
    pub fn receive(&self) -> Result<Option<T>, IpcError> {
        match self
            .port
            .receive()
            .map_err(|e| svc_err(&self.service, "receive", e))?
        {
            None => Ok(None),
            Some(sample) => {
                let v = *sample.payload();
                if v.version() != CONTRACT_VERSION {
                    return Err(IpcError::Version {
                        service: self.service.clone(),
                        found: v.version(),
                        expected: CONTRACT_VERSION,
                    });
                }
                Ok(Some(v))
            }
        }
    }

    /// As [`TopicSubscriber::receive`], with the process id of the sample's publisher: the
    /// sample header names its publisher port, the service's dynamic configuration the node
    /// that created the port, whose unique id encodes the creating process's pid (None if the
    /// port is gone or the id cannot be read). For logging who sent something — not an
    /// authentication: iceoryx2 0.10 does not authenticate publishers (docs/safety-monitor.md,
    /// threat model). A sample with a foreign contract version is an error (and consumed).
    pub fn receive_with_sender(&self) -> Result<Option<(T, Option<i32>)>, IpcError> {
        use iceoryx2::service::port_factory::PortFactory as _;
        let Some(sample) = self
            .port
            .receive()
            .map_err(|e| svc_err(&self.service, "receive", e))?
        else {
            return Ok(None);
        };
        let v = *sample.payload();
        if v.version() != CONTRACT_VERSION {
            return Err(IpcError::Version {
                service: self.service.clone(),
                found: v.version(),
                expected: CONTRACT_VERSION,
            });
        }
        let id = sample.header().publisher_id();
        let mut pid = None;
        self.factory.dynamic_config().list_publishers(|d| {
            if d.publisher_id == id {
                pid = d.node_id.pid::<ipc::Service>().ok().map(|p| p.value());
                CallbackProgression::Stop
            } else {
                CallbackProgression::Continue
            }
        });
        Ok(Some((v, pid)))
    }

    /// The publishers currently connected to this service (iceoryx2's dynamic service
    /// configuration, shared memory: no syscall, no allocation): fills `out` with up to
    /// `out.len()` of them and returns how many there are in total.
    pub fn publishers(&self, out: &mut [PublisherInfo]) -> usize {
        use iceoryx2::service::port_factory::PortFactory as _;
        let mut n = 0;
        self.factory.dynamic_config().list_publishers(|d| {
            if let Some(slot) = out.get_mut(n) {
                slot.pid = d.node_id.pid::<ipc::Service>().ok().map(|p| p.value());
            }
            n += 1;
            CallbackProgression::Continue
        });
        n
    }

    /// Drains the buffer, calling `f` for every valid sample in order; returns how many were
    /// delivered. Samples with a foreign version are skipped and reported as the error after draining.
    pub fn drain(&self, mut f: impl FnMut(&T)) -> Result<usize, IpcError> {
        let mut n = 0;
        let mut first_err = None;
        loop {
            match self.receive() {
                Ok(Some(v)) => {
                    f(&v);
                    n += 1;
                }
                Ok(None) => break,
                Err(e @ IpcError::Version { .. }) => {
                    first_err.get_or_insert(e);
                }
                Err(e) => return Err(e),
            }
        }
        match first_err {
            Some(e) => Err(e),
            None => Ok(n),
        }
    }

    /// Drains the buffer and returns only the newest sample (for cyclic readers that want the latest value).
    pub fn latest(&self) -> Result<Option<T>, IpcError> {
        let mut last = None;
        self.drain(|v| last = Some(*v))?;
        Ok(last)
    }

    pub fn service_name(&self) -> &str {
        &self.service
    }
}

/// Wakes processes waiting on [`WakeupListener`].
pub struct WakeupNotifier {
    port: Notifier<ipc::Service>,
    service: String,
}

impl WakeupNotifier {
    pub fn notify(&self) -> Result<(), IpcError> {
        self.port
            .notify()
            .map(|_| ())
            .map_err(|e| svc_err(&self.service, "notify", e))
    }
}

/// Listens for "a setpoint was published" without blocking: the owner multiplexes its file
/// descriptor with other sources (drive-io: the CAN socket) and drains it when readable.
pub struct SetpointReadyListener {
    port: Listener<ipc::Service>,
    service: String,
}

impl SetpointReadyListener {
    /// The descriptor that becomes readable when a notification is pending (iceoryx2 0.10's
    /// IPC event is a unix datagram socket; valid as long as the listener lives).
    pub fn raw_fd(&self) -> std::os::fd::RawFd {
        use iceoryx2::prelude::FileDescriptorBased;
        // SAFETY: the descriptor is owned by the listener port and outlives the returned
        // number only as long as `self`; callers use it for poll(2), never close it.
        unsafe { self.port.file_descriptor().native_handle() }
    }

    /// Consumes every pending notification without blocking; true if there was one.
    pub fn drain(&self) -> Result<bool, IpcError> {
        let n = self
            .port
            .try_wait(|_| {})
            .map_err(|e| svc_err(&self.service, "try_wait", e))?;
        Ok(n > 0)
    }
}

/// Sleeps until a wake-up is signalled.
pub struct WakeupListener {
    port: Listener<ipc::Service>,
    service: String,
}

impl WakeupListener {
    /// Waits up to `timeout`; returns true if at least one wake-up arrived.
    pub fn wait(&self, timeout: Duration) -> Result<bool, IpcError> {
        let mut woke = false;
        self.port
            .timed_wait(|_| woke = true, timeout)
            .map_err(|e| svc_err(&self.service, "timed_wait", e))?;
        Ok(woke)
    }
}
