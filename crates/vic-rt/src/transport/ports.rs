//! The iceoryx2 ports of each role. A process opens the ports of its role and nothing else:
//! [`BoardPorts`] (the board daemon), [`CentralPorts`] (the planner), [`ToolPorts`] (`vic
//! inject`, the only tool that publishes), [`ObserverPorts`] (`vic status`, `vic monitor`: read
//! only), [`MonitorPorts`] (`vic monitor` on a terminal: read only, with the states) and
//! [`RecorderPorts`] (`vic record`: read only). A role that does not publish a message
//! has no method to publish it, so a wrong call is a compile error, not a run-time one; a role
//! that does not publish takes no publisher slot, so observers cannot lock `vic inject` out.
//!
//! Every role shares one [`Session`] (the node of the namespace, the service settings); the
//! planner and `vic inject` share one [`BoardObserver`] (the board's states, telemetry and
//! events), the read-only tools a [`BoardWatch`] (telemetry and events only: no subscriber on the
//! 1 kHz state stream, which would cost the board's loop a delivery per tick).

use super::error::TransportError;
use super::protocol::{BoardEvent, CommandSlice, Control, Disturbance, StateMsg, Telemetry};
use super::relay::{Relay, RelayNotifier};
use super::service::Service as Ipc;
pub use super::session::{EVENT_SERVICE, STATE_BUFFER, Session, Topic};
use super::session::{Pub, Sub, drain, latest, send};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use std::time::{Duration, Instant};

/// The limits, here too because the protocol document lists them with the ports.
pub use super::limits::{
    MAX_LISTENERS, MAX_NODES, MAX_NOTIFIERS, MAX_PUBLISHERS, MAX_RELAY_NOTIFIERS, MAX_SUBSCRIBERS,
};

/// Publishes `value` on `port`, then wakes a bridge beside this process: every message the
/// link forwards goes out this way (the notify costs one atomic load while no bridge listens).
fn send_relayed<T: Topic>(
    session: &Session,
    port: &Pub<T>,
    relay: &RelayNotifier,
    value: &T,
) -> Result<(), TransportError> {
    let sent = send(session, port, value);
    relay.notify();
    sent
}

/// The board's node name: how a second board finds the first.
pub(crate) const BOARD_NODE: &str = "vic-board";
/// The central process's node name: how a second one finds the first, and how the monitor
/// tells a board between trials from one without a central process.
pub const CENTRAL_NODE: &str = "vic-planner";
/// The node name of `vic inject` (the one tool with a publisher).
pub(crate) const INJECT_NODE: &str = "vic-inject";
/// The node name of the read-only tools (`vic status`, `vic monitor`).
pub(crate) const OBSERVER_NODE: &str = "vic-observer";

/// The board's ports: it receives commands, control requests and disturbances, publishes its
/// state and telemetry, and wakes the listeners when something was applied.
pub struct BoardPorts {
    state: Pub<StateMsg>,
    telemetry: Pub<Telemetry>,
    commands: Sub<CommandSlice>,
    controls: Sub<Control>,
    disturbances: Sub<Disturbance>,
    events: Notifier<Ipc>,
    /// Wakes a bridge beside the board (free while none listens: [`RelayNotifier::notify`]).
    relay: RelayNotifier,
    session: Session,
}

impl BoardPorts {
    /// Connects a board to namespace `ns`. Refused while another board runs there (two plants
    /// would answer one planner).
    pub fn open(ns: &str) -> Result<BoardPorts, TransportError> {
        let session = Session::open(ns, BOARD_NODE)?;
        if let Some(&pid) = session.same_name_alive.first() {
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
            events: session.notifier()?,
            relay: RelayNotifier::open(&session, Relay::FromBoard)?,
            session,
        })
    }

    /// The node this board holds in its namespace.
    pub fn session(&self) -> &Session {
        &self.session
    }
    /// Publishes the plant state.
    pub fn publish_state(&self, s: &StateMsg) -> Result<(), TransportError> {
        send_relayed(&self.session, &self.state, &self.relay, s)
    }
    /// Publishes telemetry.
    pub fn publish_telemetry(&self, t: &Telemetry) -> Result<(), TransportError> {
        send_relayed(&self.session, &self.telemetry, &self.relay, t)
    }
    /// Every command slice received since the last call, oldest first.
    pub fn drain_commands(&self, f: impl FnMut(&CommandSlice)) -> usize {
        drain(&self.commands, f)
    }
    /// The newest command slice received since the last call, if any.
    #[cfg(test)]
    pub(crate) fn latest_command(&self) -> Option<CommandSlice> {
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
        self.relay.notify();
    }
}

/// What every observer sees of the board: its telemetry and its events (no states).
pub struct BoardWatch {
    telemetry: Sub<Telemetry>,
    events: Listener<Ipc>,
}

impl BoardWatch {
    fn open(session: &Session) -> Result<BoardWatch, TransportError> {
        Ok(BoardWatch {
            telemetry: session.subscriber()?,
            events: session.listener()?,
        })
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

    /// Whether the board signalled an event since the last call, without blocking (the bridge
    /// checks it on every wake-up).
    #[cfg(feature = "zenoh")]
    pub(crate) fn take_event(&self) -> bool {
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

/// What the planner and `vic inject` see of the board: its states, its telemetry and its events.
/// Dereferences to its [`BoardWatch`].
pub struct BoardObserver {
    states: Sub<StateMsg>,
    watch: BoardWatch,
}

impl BoardObserver {
    fn open(session: &Session) -> Result<BoardObserver, TransportError> {
        Ok(BoardObserver {
            states: session.subscriber()?,
            watch: BoardWatch::open(session)?,
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
}

impl std::ops::Deref for BoardObserver {
    type Target = BoardWatch;
    fn deref(&self) -> &BoardWatch {
        &self.watch
    }
}

/// The central controller's ports: it publishes command slices and control requests and
/// observes the board. Dereferences to its [`BoardObserver`].
pub struct CentralPorts {
    commands: Pub<CommandSlice>,
    controls: Pub<Control>,
    relay: RelayNotifier,
    observer: BoardObserver,
    session: Session,
}

impl CentralPorts {
    /// Connects a central process to namespace `ns`. Refused while another one runs there (two
    /// streams of commands would fight over one board).
    pub fn open(ns: &str) -> Result<CentralPorts, TransportError> {
        let session = Session::open(ns, CENTRAL_NODE)?;
        if let Some(&pid) = session.same_name_alive.first() {
            return Err(TransportError::CentralAlreadyRunning {
                namespace: ns.to_string(),
                pid,
            });
        }
        Ok(CentralPorts {
            commands: session.publisher()?,
            controls: session.publisher()?,
            relay: RelayNotifier::open(&session, Relay::ToBoard)?,
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
        send_relayed(&self.session, &self.commands, &self.relay, c)
    }
    /// Publishes a control request.
    pub fn publish_control(&self, c: &Control) -> Result<(), TransportError> {
        send_relayed(&self.session, &self.controls, &self.relay, c)
    }
}

impl std::ops::Deref for CentralPorts {
    type Target = BoardObserver;
    fn deref(&self) -> &BoardObserver {
        &self.observer
    }
}

/// The ports of `vic inject`: it publishes disturbances and observes the board (its states carry
/// the acknowledgement). Dereferences to its [`BoardObserver`].
pub struct ToolPorts {
    disturbances: Pub<Disturbance>,
    relay: RelayNotifier,
    observer: BoardObserver,
    session: Session,
}

impl ToolPorts {
    /// Connects `vic inject` (or another sender of disturbances) to namespace `ns`.
    pub fn open(ns: &str) -> Result<ToolPorts, TransportError> {
        let session = Session::open(ns, INJECT_NODE)?;
        Ok(ToolPorts {
            disturbances: session.publisher()?,
            relay: RelayNotifier::open(&session, Relay::ToBoard)?,
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
        send_relayed(&self.session, &self.disturbances, &self.relay, d)
    }
}

impl std::ops::Deref for ToolPorts {
    type Target = BoardObserver;
    fn deref(&self) -> &BoardObserver {
        &self.observer
    }
}

/// The ports of a read-only tool: the node `vic-observer` and `W`, what it reads of the board,
/// with no publisher. Dereferences to its `W`.
pub struct ReadOnlyPorts<W> {
    watch: W,
    session: Session,
}

/// What a read-only tool opens on its session.
pub trait ReadOnly: Sized {
    fn open_on(session: &Session) -> Result<Self, TransportError>;
}

impl ReadOnly for BoardWatch {
    fn open_on(session: &Session) -> Result<Self, TransportError> {
        BoardWatch::open(session)
    }
}

impl ReadOnly for BoardObserver {
    fn open_on(session: &Session) -> Result<Self, TransportError> {
        BoardObserver::open(session)
    }
}

/// `vic status` and the piped `vic monitor`: the board's telemetry and events, no state
/// subscriber.
pub type ObserverPorts = ReadOnlyPorts<BoardWatch>;

/// `vic monitor` on a terminal: the telemetry and the board's states too, for its rolling plots.
/// Each costs the board's loop a delivery per tick, so only the live view takes one.
pub type MonitorPorts = ReadOnlyPorts<BoardObserver>;

impl<W: ReadOnly> ReadOnlyPorts<W> {
    /// Connects a read-only tool to namespace `ns` (node `vic-observer`, like every read-only
    /// tool).
    pub fn open(ns: &str) -> Result<Self, TransportError> {
        let session = Session::open(ns, OBSERVER_NODE)?;
        Ok(ReadOnlyPorts {
            watch: W::open_on(&session)?,
            session,
        })
    }
    /// The node this tool holds in its namespace.
    pub fn session(&self) -> &Session {
        &self.session
    }
}

impl<W> std::ops::Deref for ReadOnlyPorts<W> {
    type Target = W;
    fn deref(&self) -> &W {
        &self.watch
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
        RecorderPorts::open_as(ns, "vic-recorder")
    }
    /// The same under another node name (`vic status` lists the observers by it).
    pub fn open_as(ns: &str, node_name: &str) -> Result<RecorderPorts, TransportError> {
        let session = Session::open(ns, node_name)?;
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
    pub(crate) fn drain_telemetry(&self, f: impl FnMut(&Telemetry)) -> usize {
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

/// A sender of every kind of message under its own node name (`vic-raw-sender`), for tests and
/// `scripts/soak.sh` to play a hostile or broken client beside a running planner (which would
/// refuse a second [`CentralPorts`]). It publishes whatever it is given, unchecked.
#[doc(hidden)]
pub struct RawPorts {
    commands: Pub<CommandSlice>,
    controls: Pub<Control>,
    disturbances: Pub<Disturbance>,
    relay: RelayNotifier,
    session: Session,
}

#[doc(hidden)]
impl RawPorts {
    /// Connects a raw sender to namespace `ns`.
    pub fn open(ns: &str) -> Result<RawPorts, TransportError> {
        let session = Session::open(ns, RAW_NODE)?;
        Ok(RawPorts {
            commands: session.publisher()?,
            controls: session.publisher()?,
            disturbances: session.publisher()?,
            relay: RelayNotifier::open(&session, Relay::ToBoard)?,
            session,
        })
    }
    /// Publishes a command slice as is.
    pub fn publish_command(&self, c: &CommandSlice) -> Result<(), TransportError> {
        send_relayed(&self.session, &self.commands, &self.relay, c)
    }
    /// Publishes a control request as is.
    pub fn publish_control(&self, c: &Control) -> Result<(), TransportError> {
        send_relayed(&self.session, &self.controls, &self.relay, c)
    }
    /// Publishes a disturbance as is.
    pub fn publish_disturbance(&self, d: &Disturbance) -> Result<(), TransportError> {
        send_relayed(&self.session, &self.disturbances, &self.relay, d)
    }
}

/// The node name of a raw sender ([`RawPorts`]).
pub(crate) const RAW_NODE: &str = "vic-raw-sender";

/// Whether a board is alive in the namespace (it publishes telemetry within `timeout`). Cheap
/// enough to call from tools, not from a loop.
pub fn board_present(ns: &str, timeout: Duration) -> Result<bool, TransportError> {
    Ok(ObserverPorts::open(ns)?
        .wait_for_telemetry(timeout)
        .is_some())
}

#[cfg(test)]
mod tests {
    use super::super::clock::monotonic_ns;
    use super::super::namespace::{namespace_files, remove_namespace};
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
