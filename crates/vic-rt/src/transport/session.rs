//! One process's node in a namespace and the services it opens: the message types with their
//! service settings ([`Topic`]), port creation that names the limit and its holders when a service
//! is full, and plain send / drain helpers for the role types of [`super::ports`].

use super::error::{PortKind, TransportError};
use super::limits::{
    MAX_LISTENERS, MAX_NODES, MAX_NOTIFIERS, MAX_PUBLISHERS, MAX_SUBSCRIBERS, too_many,
};
use super::namespace::{any_node_alive, config, dead_nodes_in, live_nodes_named};
use super::namespace::{
    check_namespace_owner, ensure_root_dir, remove_namespace, restrict_namespace_files,
};
use super::protocol::{CommandSlice, Control, Disturbance, StateMsg, Telemetry};
use super::service::Service as Ipc;
use super::service::create_plain_global_file;
use iceoryx2::identifiers::UniqueNodeId;
use iceoryx2::node::NodeCreationFailure;
use iceoryx2::port::listener::{Listener, ListenerCreateError};
use iceoryx2::port::notifier::{Notifier, NotifierCreateError};
use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::prelude::*;
use iceoryx2::service::Service as IpcService;
use iceoryx2::service::builder::event::{EventOpenError, EventOpenOrCreateError};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};

/// Subscriber buffer of the state service: a 50 Hz reader sees every 1 kHz state.
pub const STATE_BUFFER: usize = 128;

/// A message type with its service: the name, how many past samples a late subscriber gets and
/// how many a subscriber buffers.
pub trait Topic: std::fmt::Debug + ZeroCopySend + Copy + 'static {
    const SERVICE: &'static str;
    const HISTORY: usize;
    const BUFFER: usize;
}

impl Topic for StateMsg {
    const SERVICE: &'static str = "vic/state";
    const HISTORY: usize = 1;
    const BUFFER: usize = STATE_BUFFER;
}
impl Topic for Telemetry {
    const SERVICE: &'static str = "vic/telemetry";
    const HISTORY: usize = 1;
    const BUFFER: usize = 1;
}
impl Topic for CommandSlice {
    const SERVICE: &'static str = "vic/command";
    const HISTORY: usize = 0;
    const BUFFER: usize = 8;
}
impl Topic for Control {
    const SERVICE: &'static str = "vic/control";
    const HISTORY: usize = 0;
    const BUFFER: usize = 8;
}
impl Topic for Disturbance {
    const SERVICE: &'static str = "vic/disturbance";
    const HISTORY: usize = 0;
    const BUFFER: usize = 8;
}

/// The board's event service ([`super::protocol::BoardEvent`] ids).
pub const EVENT_SERVICE: &str = "vic/board-event";

pub(super) type Pub<T, S = Ipc> = Publisher<S, T, ()>;
pub(super) type Sub<T, S = Ipc> = Subscriber<S, T, ()>;
type PubSubService<T, S> =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<S, T, ()>;
pub(super) type EventService<S = Ipc> = iceoryx2::service::port_factory::event::PortFactory<S>;

/// One process's node in a namespace. Drop it after its ports (declare it last): the last process
/// of a namespace to leave also removes the namespace's files, so that a clean shutdown leaves
/// nothing in `/dev/shm`.
///
/// `S` is the iceoryx2 service type of the node and its ports: vic's single-threaded [`Ipc`]
/// (every daemon), or its thread-safe sibling ([`super::service::ThreadSafe`], the bridge's
/// publishers that run on Zenoh's threads). Both use the same resources, so their ports talk.
pub struct Session<S: IpcService = Ipc> {
    namespace: String,
    config: Config,
    node: Option<Node<S>>,
    /// Dead nodes of the namespace whose resources were removed when this session opened.
    cleaned_dead_nodes: usize,
    /// Process ids of the other live nodes with this session's node name when it opened.
    pub(super) same_name_alive: Vec<u32>,
}

impl<S: IpcService> Drop for Session<S> {
    fn drop(&mut self) {
        self.node = None;
        if !any_node_alive(&self.config) {
            remove_namespace(&self.namespace);
        }
    }
}

impl<S: IpcService> Session<S> {
    /// Creates the node `node_name` in namespace `ns`, removing what killed processes left.
    pub(super) fn open(ns: &str, node_name: &str) -> Result<Session<S>, TransportError> {
        set_log_level(LogLevel::Error);
        let cfg = config(ns)?;
        // The private directory first (iceoryx2 would create it with its own modes), then no
        // file of the namespace may belong to someone else.
        ensure_root_dir()?;
        check_namespace_owner(ns)?;
        // The plain `ipc` service's global file, owner-only, for the Python client to open
        // (it would create a missing one world-writable).
        create_plain_global_file(&cfg)
            .map_err(|e| TransportError::ipc(ns, "cannot create the global file in /dev/shm", e))?;
        let name = NodeName::new(node_name).map_err(|e| TransportError::ipc(ns, "node name", e))?;
        // Dead nodes (killed processes) are counted before our node's creation, which already
        // removes some of their resources.
        let dead_before = dead_nodes_in(&cfg);
        // A process that leaves the namespace as the last node removes its files (`Drop`),
        // the node counter's among them; one that does so while this node is being created
        // takes the counter away under it (seen: a board started while `vic status` polled).
        // The counter is made again on the next try.
        let mut tries = 0;
        let node = loop {
            match NodeBuilder::new()
                .name(&name)
                .config(&cfg)
                .signal_handling_mode(SignalHandlingMode::Disabled)
                .create::<S>()
            {
                Err(NodeCreationFailure::UnableToGenerateUniqueNodeId) if tries < 5 => {
                    tries += 1;
                    std::thread::sleep(std::time::Duration::from_millis(10));
                }
                r => break r.map_err(|e| TransportError::ipc(ns, "cannot create a node", e))?,
            }
        };
        // The resources of the rest are removed here so that the services open cleanly.
        let (same_name_alive, _) = live_nodes_named(ns, &cfg, node_name, node.id())?;
        let cleaned_dead_nodes = dead_before.saturating_sub(dead_nodes_in(&cfg));
        restrict_namespace_files(ns);
        Ok(Session {
            namespace: ns.to_string(),
            config: cfg,
            node: Some(node),
            cleaned_dead_nodes,
            same_name_alive,
        })
    }

    fn node(&self) -> &Node<S> {
        self.node
            .as_ref()
            .expect("the node lives as long as the session")
    }

    /// The error of a service that already has its `max` nodes (processes).
    fn too_many_nodes(&self, service: &'static str, max: usize) -> TransportError {
        too_many(
            &self.namespace,
            &self.config,
            service,
            PortKind::Node,
            max,
            None,
        )
    }

    /// The error of a service whose ports of `kind` are all taken: `list` walks the ports in
    /// use and reports each one's node, so the error can name the processes that hold them.
    fn too_many_ports(
        &self,
        service: &'static str,
        kind: PortKind,
        max: usize,
        list: impl FnOnce(&mut dyn FnMut(UniqueNodeId)),
    ) -> TransportError {
        let mut ids = Vec::new();
        list(&mut |id| ids.push(id));
        too_many(
            &self.namespace,
            &self.config,
            service,
            kind,
            max,
            Some(&ids),
        )
    }

    fn service<T: Topic>(&self) -> Result<PubSubService<T, S>, TransportError> {
        let ns = &self.namespace;
        let name =
            ServiceName::new(T::SERVICE).map_err(|e| TransportError::ipc(ns, T::SERVICE, e))?;
        self.node()
            .service_builder(&name)
            .publish_subscribe::<T>()
            .max_publishers(MAX_PUBLISHERS)
            .max_subscribers(MAX_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .subscriber_max_buffer_size(STATE_BUFFER)
            .history_size(T::HISTORY)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(|e| match e {
                PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                    PublishSubscribeOpenError::ExceedsMaxNumberOfNodes,
                ) => self.too_many_nodes(T::SERVICE, MAX_NODES),
                e => TransportError::ipc(ns, format!("service {}", T::SERVICE), e),
            })
    }

    pub(super) fn publisher<T: Topic>(&self) -> Result<Pub<T, S>, TransportError> {
        let svc = self.service::<T>()?;
        svc.publisher_builder().create().map_err(|e| match e {
            PublisherCreateError::ExceedsMaxSupportedPublishers => self.too_many_ports(
                T::SERVICE,
                PortKind::Publisher,
                svc.static_config().max_publishers(),
                |push| {
                    svc.dynamic_config().list_publishers(|d| {
                        push(d.node_id);
                        CallbackProgression::Continue
                    })
                },
            ),
            e => TransportError::ipc(&self.namespace, format!("{} publisher", T::SERVICE), e),
        })
    }

    pub(super) fn subscriber<T: Topic>(&self) -> Result<Sub<T, S>, TransportError> {
        self.subscriber_with_buffer(T::BUFFER)
    }

    pub(super) fn subscriber_with_buffer<T: Topic>(
        &self,
        buffer: usize,
    ) -> Result<Sub<T, S>, TransportError> {
        let svc = self.service::<T>()?;
        let builder = svc.subscriber_builder().buffer_size(buffer);
        builder.create().map_err(|e| match e {
            SubscriberCreateError::ExceedsMaxSupportedSubscribers => self.too_many_ports(
                T::SERVICE,
                PortKind::Subscriber,
                svc.static_config().max_subscribers(),
                |push| {
                    svc.dynamic_config().list_subscribers(|d| {
                        push(d.node_id);
                        CallbackProgression::Continue
                    })
                },
            ),
            e => TransportError::ipc(&self.namespace, format!("{} subscriber", T::SERVICE), e),
        })
    }

    /// The event service `name` (the board's events or a relay service).
    fn event_service(
        &self,
        name: &'static str,
        max_notifiers: usize,
    ) -> Result<EventService<S>, TransportError> {
        let ns = &self.namespace;
        let service = ServiceName::new(name).map_err(|e| TransportError::ipc(ns, name, e))?;
        self.node()
            .service_builder(&service)
            .event()
            .max_notifiers(max_notifiers)
            .max_listeners(MAX_LISTENERS)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| match e {
                EventOpenOrCreateError::EventOpenError(EventOpenError::ExceedsMaxNumberOfNodes) => {
                    self.too_many_nodes(name, MAX_NODES)
                }
                e => TransportError::ipc(ns, format!("service {name}"), e),
            })
    }

    /// A listener of the board's events.
    pub(super) fn listener(&self) -> Result<Listener<S>, TransportError> {
        self.listener_on(EVENT_SERVICE, MAX_NOTIFIERS)
    }

    /// A listener of the event service `name`.
    pub(super) fn listener_on(
        &self,
        name: &'static str,
        max_notifiers: usize,
    ) -> Result<Listener<S>, TransportError> {
        let svc = self.event_service(name, max_notifiers)?;
        svc.listener_builder().create().map_err(|e| match e {
            ListenerCreateError::ExceedsMaxSupportedListeners => self.too_many_ports(
                name,
                PortKind::Listener,
                svc.static_config().max_listeners(),
                |push| {
                    svc.dynamic_config().list_listeners(|d| {
                        push(d.node_id);
                        CallbackProgression::Continue
                    })
                },
            ),
            e => TransportError::ipc(&self.namespace, format!("{name} listener"), e),
        })
    }

    /// The board's notifier of its events.
    pub(super) fn notifier(&self) -> Result<Notifier<S>, TransportError> {
        Ok(self.notifier_on(EVENT_SERVICE, MAX_NOTIFIERS)?.0)
    }

    /// A notifier of the event service `name`, with the service (which tells how many listeners
    /// it has).
    pub(super) fn notifier_on(
        &self,
        name: &'static str,
        max_notifiers: usize,
    ) -> Result<(Notifier<S>, EventService<S>), TransportError> {
        let svc = self.event_service(name, max_notifiers)?;
        let notifier = svc.notifier_builder().create().map_err(|e| match e {
            NotifierCreateError::ExceedsMaxSupportedNotifiers => self.too_many_ports(
                name,
                PortKind::Notifier,
                svc.static_config().max_notifiers(),
                |push| {
                    svc.dynamic_config().list_notifiers(|d| {
                        push(d.node_id);
                        CallbackProgression::Continue
                    })
                },
            ),
            e => TransportError::ipc(&self.namespace, format!("{name} notifier"), e),
        })?;
        Ok((notifier, svc))
    }

    /// The namespace of this session.
    pub fn namespace(&self) -> &str {
        &self.namespace
    }

    /// Dead nodes of the namespace whose resources were removed when this session opened.
    pub fn cleaned_dead_nodes(&self) -> usize {
        self.cleaned_dead_nodes
    }
}

pub(super) fn send<T: Topic, S: IpcService>(
    session: &Session<S>,
    port: &Pub<T, S>,
    value: &T,
) -> Result<(), TransportError> {
    port.send_copy(*value).map(|_| ()).map_err(|e| {
        TransportError::ipc(&session.namespace, format!("cannot send {}", T::SERVICE), e)
    })
}

/// Calls `f` on every message waiting on `port`, oldest first; returns how many there were.
pub(super) fn drain<T: Topic, S: IpcService>(port: &Sub<T, S>, mut f: impl FnMut(&T)) -> usize {
    let mut n = 0;
    while let Ok(Some(sample)) = port.receive() {
        f(&sample);
        n += 1;
    }
    n
}

/// The newest message waiting on `port`, if any (the older ones are consumed).
pub(super) fn latest<T: Topic, S: IpcService>(port: &Sub<T, S>) -> Option<T> {
    let mut last = None;
    drain(port, |m| last = Some(*m));
    last
}
