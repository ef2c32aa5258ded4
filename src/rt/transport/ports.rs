//! The iceoryx2 ports of each role. A process opens the ports of its role and nothing else:
//! [`BoardPorts`] (the board daemon), [`CentralPorts`] (the planner) and [`ToolPorts`] (`vic
//! inject`, `status`, `monitor`). A role that does not publish a message has no method to publish
//! it, so a wrong call is a compile error, not a run-time one.
//!
//! Every role shares one [`Session`] (the node of the namespace, the service settings) and the
//! planner and the tools share one [`BoardObserver`] (the board's states, telemetry and events).

use super::error::TransportError;
use super::namespace::{any_node_alive, config, dead_nodes_in, live_nodes_named};
use super::namespace::{
    check_namespace_owner, ensure_root_dir, remove_namespace, restrict_namespace_files,
};
use super::protocol::{BoardEvent, CommandSlice, Control, Disturbance, StateMsg, Telemetry};
use super::service::Service as Ipc;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::{Publisher, PublisherCreateError};
use iceoryx2::port::subscriber::{Subscriber, SubscriberCreateError};
use iceoryx2::prelude::*;
use std::time::{Duration, Instant};

/// Subscriber buffer of the state service: a 50 Hz reader sees every 1 kHz state.
pub const STATE_BUFFER: usize = 128;

/// The limits of every service of a namespace, in one place. Sized for one board, one central
/// process, one recorder, `vic inject` and at least 8 read-only observers (`vic status`,
/// `vic monitor`, a Python client), with room to spare:
/// - publishers per message service: the board or the central process, plus a tool or a
///   test's hostile sender;
pub const MAX_PUBLISHERS: usize = 4;
/// - subscribers per message service: board, central, recorder, inject and 8 observers = 12;
pub const MAX_SUBSCRIBERS: usize = 16;
/// - nodes (processes) per service;
pub const MAX_NODES: usize = 32;
/// - notifiers and listeners of the board's event service (every observer listens).
pub const MAX_NOTIFIERS: usize = 4;
pub const MAX_LISTENERS: usize = 24;

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
/// The board's node name: how a second board finds the first.
const BOARD_NODE: &str = "vic-board";

type Pub<T> = Publisher<Ipc, T, ()>;
type Sub<T> = Subscriber<Ipc, T, ()>;
type PubSubService<T> = iceoryx2::service::port_factory::publish_subscribe::PortFactory<Ipc, T, ()>;
type EventService = iceoryx2::service::port_factory::event::PortFactory<Ipc>;

/// One process's node in a namespace. Drop it after its ports (declare it last): the last process
/// of a namespace to leave also removes the namespace's files, so that a clean shutdown leaves
/// nothing in `/dev/shm`.
pub struct Session {
    namespace: String,
    config: Config,
    node: Option<Node<Ipc>>,
    /// Dead nodes of the namespace whose resources were removed when this session opened.
    cleaned_dead_nodes: usize,
    /// Process ids of the other boards alive in the namespace when this session opened.
    boards_alive: Vec<u32>,
}

impl Drop for Session {
    fn drop(&mut self) {
        self.node = None;
        if !any_node_alive(&self.config) {
            remove_namespace(&self.namespace);
        }
    }
}

impl Session {
    /// Creates the node `node_name` in namespace `ns`, removing what killed processes left.
    fn open(ns: &str, node_name: &str) -> Result<Session, TransportError> {
        set_log_level(LogLevel::Error);
        let cfg = config(ns)?;
        // The private directory first (iceoryx2 would create it with its own modes), then no
        // file of the namespace may belong to someone else.
        ensure_root_dir()?;
        check_namespace_owner(ns)?;
        let name = NodeName::new(node_name).map_err(|e| TransportError::ipc(ns, "node name", e))?;
        // Dead nodes (killed processes) are counted before our node's creation, which already
        // removes some of their resources.
        let dead_before = dead_nodes_in(&cfg);
        let node = NodeBuilder::new()
            .name(&name)
            .config(&cfg)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<Ipc>()
            .map_err(|e| TransportError::ipc(ns, "cannot create a node", e))?;
        // The resources of the rest are removed here so that the services open cleanly.
        let (boards_alive, _) = live_nodes_named(ns, &cfg, BOARD_NODE, node.id())?;
        let cleaned_dead_nodes = dead_before.saturating_sub(dead_nodes_in(&cfg));
        restrict_namespace_files(ns);
        Ok(Session {
            namespace: ns.to_string(),
            config: cfg,
            node: Some(node),
            cleaned_dead_nodes,
            boards_alive,
        })
    }

    fn node(&self) -> &Node<Ipc> {
        self.node
            .as_ref()
            .expect("the node lives as long as the session")
    }

    fn service<T: Topic>(&self) -> Result<PubSubService<T>, TransportError> {
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
            .map_err(|e| TransportError::ipc(ns, format!("service {}", T::SERVICE), e))
    }

    fn too_many(&self, service: &'static str, port: &'static str) -> TransportError {
        TransportError::TooManyPorts {
            namespace: self.namespace.clone(),
            service,
            port,
        }
    }

    fn publisher<T: Topic>(&self) -> Result<Pub<T>, TransportError> {
        self.service::<T>()?
            .publisher_builder()
            .create()
            .map_err(|e| match e {
                PublisherCreateError::ExceedsMaxSupportedPublishers => {
                    self.too_many(T::SERVICE, "publisher")
                }
                e => TransportError::ipc(&self.namespace, format!("{} publisher", T::SERVICE), e),
            })
    }

    fn subscriber<T: Topic>(&self) -> Result<Sub<T>, TransportError> {
        self.subscriber_with_buffer(T::BUFFER)
    }

    fn subscriber_with_buffer<T: Topic>(&self, buffer: usize) -> Result<Sub<T>, TransportError> {
        self.service::<T>()?
            .subscriber_builder()
            .buffer_size(buffer)
            .create()
            .map_err(|e| match e {
                SubscriberCreateError::ExceedsMaxSupportedSubscribers => {
                    self.too_many(T::SERVICE, "subscriber")
                }
                e => TransportError::ipc(&self.namespace, format!("{} subscriber", T::SERVICE), e),
            })
    }

    fn event_service(&self) -> Result<EventService, TransportError> {
        let ns = &self.namespace;
        let name = ServiceName::new(EVENT_SERVICE)
            .map_err(|e| TransportError::ipc(ns, EVENT_SERVICE, e))?;
        self.node()
            .service_builder(&name)
            .event()
            .max_notifiers(MAX_NOTIFIERS)
            .max_listeners(MAX_LISTENERS)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| TransportError::ipc(ns, format!("service {EVENT_SERVICE}"), e))
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

fn send<T: Topic>(session: &Session, port: &Pub<T>, value: &T) -> Result<(), TransportError> {
    port.send_copy(*value).map(|_| ()).map_err(|e| {
        TransportError::ipc(&session.namespace, format!("cannot send {}", T::SERVICE), e)
    })
}

/// Calls `f` on every message waiting on `port`, oldest first; returns how many there were.
fn drain<T: Topic>(port: &Sub<T>, mut f: impl FnMut(&T)) -> usize {
    let mut n = 0;
    while let Ok(Some(sample)) = port.receive() {
        f(&sample);
        n += 1;
    }
    n
}

/// The newest message waiting on `port`, if any (the older ones are consumed).
fn latest<T: Topic>(port: &Sub<T>) -> Option<T> {
    let mut last = None;
    drain(port, |m| last = Some(*m));
    last
}

/// The board's ports: it receives commands, control requests and disturbances, publishes its
/// state and telemetry, and wakes the listeners when something was applied.
pub struct BoardPorts {
    state: Pub<StateMsg>,
    telemetry: Pub<Telemetry>,
    commands: Sub<CommandSlice>,
    controls: Sub<Control>,
    disturbances: Sub<Disturbance>,
    events: Notifier<Ipc>,
    session: Session,
}

impl BoardPorts {
    /// Connects a board to namespace `ns`. Refused while another board runs there (two plants
    /// would answer one planner).
    pub fn open(ns: &str) -> Result<BoardPorts, TransportError> {
        let session = Session::open(ns, BOARD_NODE)?;
        if let Some(&pid) = session.boards_alive.first() {
            return Err(TransportError::BoardAlreadyRunning {
                namespace: ns.to_string(),
                pid,
            });
        }
        Ok(BoardPorts {
            state: session.publisher()?,
            telemetry: session.publisher()?,
            commands: session.subscriber()?,
            controls: session.subscriber()?,
            disturbances: session.subscriber()?,
            events: session
                .event_service()?
                .notifier_builder()
                .create()
                .map_err(|e| TransportError::ipc(ns, "event notifier", e))?,
            session,
        })
    }

    /// The node this board holds in its namespace.
    pub fn session(&self) -> &Session {
        &self.session
    }
    /// Publishes the plant state.
    pub fn publish_state(&self, s: &StateMsg) -> Result<(), TransportError> {
        send(&self.session, &self.state, s)
    }
    /// Publishes telemetry.
    pub fn publish_telemetry(&self, t: &Telemetry) -> Result<(), TransportError> {
        send(&self.session, &self.telemetry, t)
    }
    /// Every command slice received since the last call, oldest first.
    pub fn drain_commands(&self, f: impl FnMut(&CommandSlice)) -> usize {
        drain(&self.commands, f)
    }
    /// The newest command slice received since the last call, if any.
    pub fn latest_command(&self) -> Option<CommandSlice> {
        latest(&self.commands)
    }
    /// Every control request received since the last call.
    pub fn drain_controls(&self, f: impl FnMut(&Control)) -> usize {
        drain(&self.controls, f)
    }
    /// Every disturbance received since the last call.
    pub fn drain_disturbances(&self, f: impl FnMut(&Disturbance)) -> usize {
        drain(&self.disturbances, f)
    }
    /// Wakes the board's listeners. Without listeners this touches shared memory only.
    pub fn notify(&self, e: BoardEvent) {
        let _ = self
            .events
            .notify_with_custom_event_id(EventId::new(e as usize));
    }
}

/// What the planner and the tools see of the board: its states, its telemetry and its events.
pub struct BoardObserver {
    states: Sub<StateMsg>,
    telemetry: Sub<Telemetry>,
    events: Listener<Ipc>,
}

impl BoardObserver {
    fn open(session: &Session) -> Result<BoardObserver, TransportError> {
        Ok(BoardObserver {
            states: session.subscriber()?,
            telemetry: session.subscriber()?,
            events: session
                .event_service()?
                .listener_builder()
                .create()
                .map_err(|e| TransportError::ipc(&session.namespace, "event listener", e))?,
        })
    }

    /// Every state received since the last call, oldest first.
    pub fn drain_states(&self, f: impl FnMut(&StateMsg)) -> usize {
        drain(&self.states, f)
    }
    /// The newest state received since the last call, if any.
    pub fn latest_state(&self) -> Option<StateMsg> {
        latest(&self.states)
    }
    /// The newest telemetry received since the last call, if any.
    pub fn latest_telemetry(&self) -> Option<Telemetry> {
        latest(&self.telemetry)
    }

    /// Blocks until the board signals an event or `timeout` passes: the iceoryx2 listener
    /// sleeps in the kernel, no polling. Returns whether an event came.
    pub fn wait_event(&self, timeout: Duration) -> bool {
        let mut got = false;
        let _ = self.events.timed_wait(|_| got = true, timeout);
        // Drain what else is pending, so the next wait blocks again.
        let _ = self.events.try_wait(|_| got = true);
        got
    }

    /// Whether the board signalled an event since the last call, without blocking (a relay's
    /// loop, e.g. the bridge, polls it).
    pub fn take_event(&self) -> bool {
        let mut got = false;
        let _ = self.events.try_wait(|_| got = true);
        got
    }

    /// Waits up to `timeout` for telemetry from a board (woken by the board's events, no
    /// polling). `None`: no board answered.
    pub fn wait_for_telemetry(&self, timeout: Duration) -> Option<Telemetry> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(t) = self.latest_telemetry() {
                return Some(t);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            self.wait_event(left.min(Duration::from_millis(200)));
        }
    }
}

/// The central controller's ports: it publishes command slices and control requests and
/// observes the board. Dereferences to its [`BoardObserver`].
pub struct CentralPorts {
    commands: Pub<CommandSlice>,
    controls: Pub<Control>,
    observer: BoardObserver,
    session: Session,
}

impl CentralPorts {
    /// Connects a planner to namespace `ns`.
    pub fn open(ns: &str) -> Result<CentralPorts, TransportError> {
        let session = Session::open(ns, "vic-planner")?;
        Ok(CentralPorts {
            commands: session.publisher()?,
            controls: session.publisher()?,
            observer: BoardObserver::open(&session)?,
            session,
        })
    }
    /// The node this planner holds in its namespace.
    pub fn session(&self) -> &Session {
        &self.session
    }
    /// Publishes a command slice.
    pub fn publish_command(&self, c: &CommandSlice) -> Result<(), TransportError> {
        send(&self.session, &self.commands, c)
    }
    /// Publishes a control request.
    pub fn publish_control(&self, c: &Control) -> Result<(), TransportError> {
        send(&self.session, &self.controls, c)
    }
}

impl std::ops::Deref for CentralPorts {
    type Target = BoardObserver;
    fn deref(&self) -> &BoardObserver {
        &self.observer
    }
}

/// The command-line tools' ports: they publish disturbances and observe the board.
/// Dereferences to its [`BoardObserver`].
pub struct ToolPorts {
    disturbances: Pub<Disturbance>,
    observer: BoardObserver,
    session: Session,
}

impl ToolPorts {
    /// Connects a tool to namespace `ns`.
    pub fn open(ns: &str) -> Result<ToolPorts, TransportError> {
        let session = Session::open(ns, "vic-tool")?;
        Ok(ToolPorts {
            disturbances: session.publisher()?,
            observer: BoardObserver::open(&session)?,
            session,
        })
    }
    /// The node this tool holds in its namespace.
    pub fn session(&self) -> &Session {
        &self.session
    }
    /// Publishes a disturbance.
    pub fn publish_disturbance(&self, d: &Disturbance) -> Result<(), TransportError> {
        send(&self.session, &self.disturbances, d)
    }
}

impl std::ops::Deref for ToolPorts {
    type Target = BoardObserver;
    fn deref(&self) -> &BoardObserver {
        &self.observer
    }
}

/// A recorder's ports (`vic record`): it subscribes to every service of the namespace, with the
/// largest buffer the services allow, and publishes nothing, so it cannot disturb the board.
pub struct RecorderPorts {
    states: Sub<StateMsg>,
    telemetry: Sub<Telemetry>,
    commands: Sub<CommandSlice>,
    controls: Sub<Control>,
    disturbances: Sub<Disturbance>,
    session: Session,
}

impl RecorderPorts {
    /// Connects a recorder to namespace `ns`.
    pub fn open(ns: &str) -> Result<RecorderPorts, TransportError> {
        let session = Session::open(ns, "vic-recorder")?;
        Ok(RecorderPorts {
            states: session.subscriber_with_buffer(STATE_BUFFER)?,
            telemetry: session.subscriber_with_buffer(STATE_BUFFER)?,
            commands: session.subscriber_with_buffer(STATE_BUFFER)?,
            controls: session.subscriber_with_buffer(STATE_BUFFER)?,
            disturbances: session.subscriber_with_buffer(STATE_BUFFER)?,
            session,
        })
    }
    /// The node this recorder holds in its namespace.
    pub fn session(&self) -> &Session {
        &self.session
    }
    /// Every state received since the last call, oldest first.
    pub fn drain_states(&self, f: impl FnMut(&StateMsg)) -> usize {
        drain(&self.states, f)
    }
    /// Every telemetry message received since the last call.
    pub fn drain_telemetry(&self, f: impl FnMut(&Telemetry)) -> usize {
        drain(&self.telemetry, f)
    }
    /// Every command slice received since the last call.
    pub fn drain_commands(&self, f: impl FnMut(&CommandSlice)) -> usize {
        drain(&self.commands, f)
    }
    /// Every control request received since the last call.
    pub fn drain_controls(&self, f: impl FnMut(&Control)) -> usize {
        drain(&self.controls, f)
    }
    /// Every disturbance received since the last call.
    pub fn drain_disturbances(&self, f: impl FnMut(&Disturbance)) -> usize {
        drain(&self.disturbances, f)
    }
}

/// Whether a board is alive in the namespace (it publishes telemetry within `timeout`). Cheap
/// enough to call from tools, not from a loop.
pub fn board_present(ns: &str, timeout: Duration) -> Result<bool, TransportError> {
    Ok(ToolPorts::open(ns)?.wait_for_telemetry(timeout).is_some())
}

#[cfg(test)]
mod tests {
    use super::super::clock::monotonic_ns;
    use super::super::namespace::namespace_files;
    use super::super::protocol::Header;
    use super::*;

    #[test]
    fn state_and_commands_cross_two_nodes() {
        let ns = format!("t{}x{}", std::process::id(), monotonic_ns() % 100_000);
        {
            let board = BoardPorts::open(&ns).unwrap();
            let planner = CentralPorts::open(&ns).unwrap();
            let s = StateMsg {
                header: Header::new(7, 0),
                q: [0.5, 1.0],
                ..Default::default()
            };
            board.publish_state(&s).unwrap();
            let got = planner.latest_state().unwrap();
            assert_eq!(got.header.seq, 7);
            assert_eq!(got.q, [0.5, 1.0]);
            let mut c = CommandSlice {
                header: Header::new(3, 0),
                count: 2,
                ..Default::default()
            };
            c.knots[1].stiffness = [10.0, 20.0];
            planner.publish_command(&c).unwrap();
            let got = board.latest_command().unwrap();
            assert_eq!(got.header.seq, 3);
            assert_eq!(got.knots[1].stiffness, [10.0, 20.0]);
            assert!(board.latest_command().is_none());
            // A different namespace sees nothing.
            let other = format!("{ns}o");
            {
                let stranger = CentralPorts::open(&other).unwrap();
                board.publish_state(&s).unwrap();
                assert!(stranger.latest_state().is_none());
            }
            remove_namespace(&other);
            // A second board in the namespace is refused, with the first one's pid.
            assert!(matches!(
                BoardPorts::open(&ns),
                Err(TransportError::BoardAlreadyRunning { .. })
            ));
        }
        remove_namespace(&ns);
        assert!(
            namespace_files(&ns).is_empty(),
            "{:?}",
            namespace_files(&ns)
        );
    }
}
