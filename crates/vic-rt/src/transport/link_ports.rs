//! The publishers a relay (the Zenoh bridge) drives from Zenoh's threads: each message that
//! arrives on the link is published into the namespace inside the Zenoh callback that received it,
//! without waking another thread. They are ports of the thread-safe service type
//! ([`ThreadSafe`]: the same resources as every other port, so the board and the planner read
//! them like any other publisher's), on a node of their own ([`BRIDGE_NODE`]).
//!
//! The bridge keeps its role's ports too (the planner's and `vic inject`'s beside the board, the
//! board's beside the planner): their subscribers feed the other direction, and their node name
//! refuses a second board or planner in the namespace as it would locally. Here is only what the
//! link delivers. The board's 1 kHz loop never touches this type (its mutex per send).

use super::error::TransportError;
use super::limits::MAX_NOTIFIERS;
use super::ports::EVENT_SERVICE;
use super::protocol::{BoardEvent, CommandSlice, Control, Disturbance, StateMsg, Telemetry};
use super::relay::{Relay, RelayNotifier};
use super::service::ThreadSafe;
use super::session::{Pub, Session, Topic};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::EventId;
use std::sync::Mutex;

/// The node name of a bridge's link publishers.
pub(crate) const BRIDGE_NODE: &str = "vic-bridge";

/// The node of the ports, kept alive as long as they are and dropped after them. iceoryx2's node
/// is `Send` but not `Sync`; it is never used after opening, so the mutex is never locked: it
/// only lets the ports be shared with the callbacks' threads.
struct Node {
    _session: Mutex<Session<ThreadSafe>>,
    namespace: String,
}

impl Node {
    fn open(ns: &str) -> Result<Session<ThreadSafe>, TransportError> {
        Session::open(ns, BRIDGE_NODE)
    }

    fn keep(session: Session<ThreadSafe>) -> Node {
        Node {
            namespace: session.namespace().to_string(),
            _session: Mutex::new(session),
        }
    }

    fn send<T: Topic>(&self, port: &Pub<T, ThreadSafe>, value: &T) -> Result<(), TransportError> {
        port.send_copy(*value).map(|_| ()).map_err(|e| {
            TransportError::ipc(&self.namespace, format!("cannot send {}", T::SERVICE), e)
        })
    }
    /// [`Node::send`], then wakes another relay of the namespace, as a local publisher would
    /// (the ports' `send_relayed`).
    fn send_relayed<T: Topic>(
        &self,
        port: &Pub<T, ThreadSafe>,
        relay: &RelayNotifier<ThreadSafe>,
        value: &T,
    ) -> Result<(), TransportError> {
        let sent = self.send(port, value);
        relay.notify();
        sent
    }
}

/// What the bridge beside the board publishes: the command slices and control requests of the
/// planner on the other host, and the disturbances of its `vic inject`.
pub(crate) struct ToBoardLink {
    commands: Pub<CommandSlice, ThreadSafe>,
    controls: Pub<Control, ThreadSafe>,
    disturbances: Pub<Disturbance, ThreadSafe>,
    /// Wakes another relay of the namespace, as a local publisher would.
    relay: RelayNotifier<ThreadSafe>,
    /// Last: dropped after the ports.
    node: Node,
}

impl ToBoardLink {
    /// Opens the publishers in namespace `ns`.
    pub fn open(ns: &str) -> Result<ToBoardLink, TransportError> {
        let session = Node::open(ns)?;
        Ok(ToBoardLink {
            commands: session.publisher()?,
            controls: session.publisher()?,
            disturbances: session.publisher()?,
            relay: RelayNotifier::open(&session, Relay::ToBoard)?,
            node: Node::keep(session),
        })
    }
    /// Publishes a command slice.
    pub fn publish_command(&self, c: &CommandSlice) -> Result<(), TransportError> {
        self.node.send_relayed(&self.commands, &self.relay, c)
    }
    /// Publishes a control request.
    pub fn publish_control(&self, c: &Control) -> Result<(), TransportError> {
        self.node.send_relayed(&self.controls, &self.relay, c)
    }
    /// Publishes a disturbance.
    pub fn publish_disturbance(&self, d: &Disturbance) -> Result<(), TransportError> {
        self.node.send_relayed(&self.disturbances, &self.relay, d)
    }
}

/// What the bridge beside the planner publishes, playing the board: the board's states,
/// telemetry and events from the other host.
pub(crate) struct FromBoardLink {
    state: Pub<StateMsg, ThreadSafe>,
    telemetry: Pub<Telemetry, ThreadSafe>,
    events: Notifier<ThreadSafe>,
    relay: RelayNotifier<ThreadSafe>,
    node: Node,
}

impl FromBoardLink {
    /// Opens the publishers in namespace `ns`.
    pub fn open(ns: &str) -> Result<FromBoardLink, TransportError> {
        let session = Node::open(ns)?;
        Ok(FromBoardLink {
            state: session.publisher()?,
            telemetry: session.publisher()?,
            events: session.notifier_on(EVENT_SERVICE, MAX_NOTIFIERS)?.0,
            relay: RelayNotifier::open(&session, Relay::FromBoard)?,
            node: Node::keep(session),
        })
    }
    /// Publishes a state.
    pub fn publish_state(&self, s: &StateMsg) -> Result<(), TransportError> {
        self.node.send_relayed(&self.state, &self.relay, s)
    }
    /// Publishes telemetry and wakes the board's listeners with [`BoardEvent::Telemetry`], as
    /// the board does.
    pub fn publish_telemetry(&self, t: &Telemetry) -> Result<(), TransportError> {
        let sent = self.node.send(&self.telemetry, t);
        self.notify(BoardEvent::Telemetry);
        sent
    }
    /// Wakes the board's listeners (and a relay).
    pub fn notify(&self, e: BoardEvent) {
        let _ = self
            .events
            .notify_with_custom_event_id(EventId::new(e as usize));
        self.relay.notify();
    }
}

#[cfg(test)]
mod tests {
    use super::super::clock::monotonic_ns;
    use super::super::namespace::{namespace_files, remove_namespace};
    use super::super::ports::{BoardPorts, CentralPorts};
    use super::super::protocol::Header;
    use super::super::relay::RelayListener;
    use super::*;
    use std::os::unix::fs::PermissionsExt;
    use std::sync::Arc;
    use std::time::Duration;

    /// The link's ports may be shared with Zenoh's threads (a compile-time check).
    const _: fn() = || {
        fn shared<T: Send + Sync>() {}
        shared::<ToBoardLink>();
        shared::<FromBoardLink>();
    };

    /// Ports of the thread-safe type, used from another thread, and the daemons' single-threaded
    /// ports talk on the same services (messages and events both ways); the namespace's files
    /// stay owner-only, and go when the last node leaves.
    #[test]
    fn thread_safe_ports_talk_to_the_daemons_ports() {
        let ns = format!("lp{}x{}", std::process::id(), monotonic_ns() % 100_000);
        {
            let board = BoardPorts::open(&ns).unwrap();
            let planner = CentralPorts::open(&ns).unwrap();
            let to = Arc::new(ToBoardLink::open(&ns).unwrap());
            let from = Arc::new(FromBoardLink::open(&ns).unwrap());
            let to_board = RelayListener::open(planner.session(), Relay::ToBoard).unwrap();
            let from_board = RelayListener::open(board.session(), Relay::FromBoard).unwrap();
            let command = CommandSlice {
                header: Header::new(11, 1),
                count: 2,
                ..Default::default()
            };
            let state = StateMsg {
                header: Header::new(12, 2),
                q: [0.25, -0.5],
                ..Default::default()
            };
            let telemetry = Telemetry {
                header: Header::new(13, 3),
                ..Default::default()
            };
            std::thread::scope(|s| {
                let (to, from) = (to.clone(), from.clone());
                s.spawn(move || {
                    to.publish_command(&command).unwrap();
                    from.publish_state(&state).unwrap();
                    from.publish_telemetry(&telemetry).unwrap();
                });
            });
            let got = board
                .latest_command()
                .expect("the board got the link's command");
            assert_eq!((got.header.seq, got.count), (11, 2));
            let got = planner
                .latest_state()
                .expect("the planner got the link's state");
            assert_eq!((got.header.seq, got.q), (12, [0.25, -0.5]));
            assert_eq!(planner.latest_telemetry().map(|t| t.header.seq), Some(13));
            assert!(planner.wait_event(Duration::from_secs(1)), "no board event");
            assert!(
                to_board.take() && from_board.take(),
                "a relay was not woken"
            );
            // The daemons' ports publish on the services the link's ports opened too.
            board.publish_state(&state).unwrap();
            assert_eq!(planner.latest_state().map(|s| s.header.seq), Some(12));
            let files = namespace_files(&ns);
            assert!(files.len() > 4, "{files:?}");
            for f in &files {
                let mode = std::fs::metadata(f).unwrap().permissions().mode();
                assert_eq!(mode & 0o077, 0, "{f} is {mode:o}, not owner-only");
            }
        }
        assert!(
            namespace_files(&ns).is_empty(),
            "{:?}",
            namespace_files(&ns)
        );
        remove_namespace(&ns);
    }
}
