//! The wake-ups of a relay (the Zenoh bridge): two event services, one per direction, that only
//! a relay listens to, so a bridge sleeps until there is something to forward instead of
//! draining the namespace on a timer.
//!
//! - [`Relay::FromBoard`] (`vic/relay-from-board`): the board notifies it per published state,
//!   telemetry and event (1 kHz);
//! - [`Relay::ToBoard`] (`vic/relay-to-board`): the central process per command slice and
//!   control request, `vic inject` per disturbance.
//!
//! They are separate from the board's own event service (`vic/board-event`) so that the planner
//! and the observers, which listen there, are not woken 1000 times a second.
//!
//! **What a notification costs.** iceoryx2 0.10's `Notifier::notify` walks its listener
//! connections (on Linux each one a Unix datagram socket beside a counting bit set in shared
//! memory): with no listener it makes no system call, but it still compares the service's
//! listener list and iterates its connection slots. With a listener it sets the bit and sends one
//! datagram (`sendto`) only when the listener has consumed the previous notification; until
//! then a further notify is a compare-and-swap in shared memory. [`RelayNotifier::notify`] goes
//! further and does not call iceoryx2 at all while the service has no listener: one atomic
//! load of the service's listener count, so a board without a bridge pays that and nothing more.
//! When a listener appears, the first notify connects to it (iceoryx2 opens the socket and
//! allocates its connection list then, once per listener that joins, as for the board's own
//! events).

use super::error::TransportError;
use super::limits::MAX_RELAY_NOTIFIERS;
use super::service::Service as Ipc;
use super::session::{EventService, Session};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::PortFactory;
use iceoryx2::service::Service as IpcService;

/// The event service of each direction.
pub(crate) const FROM_BOARD_SERVICE: &str = "vic/relay-from-board";
/// See [`FROM_BOARD_SERVICE`].
pub(crate) const TO_BOARD_SERVICE: &str = "vic/relay-to-board";

/// Which way the relayed messages go.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Relay {
    /// State, telemetry and events, from the board to whoever relays them.
    FromBoard,
    /// Commands, control requests and disturbances, towards the board.
    ToBoard,
}

impl Relay {
    /// The name of the event service.
    pub fn service(self) -> &'static str {
        match self {
            Relay::FromBoard => FROM_BOARD_SERVICE,
            Relay::ToBoard => TO_BOARD_SERVICE,
        }
    }
}

/// The notifier a publisher holds beside its publishers: it wakes a relay, if one listens. `S`:
/// the service type of the publisher's session (the bridge's thread-safe ports have their own).
pub(crate) struct RelayNotifier<S: IpcService = Ipc> {
    notifier: Notifier<S>,
    service: EventService<S>,
}

impl<S: IpcService> RelayNotifier<S> {
    pub(super) fn open(session: &Session<S>, relay: Relay) -> Result<Self, TransportError> {
        let (notifier, service) = session.notifier_on(relay.service(), MAX_RELAY_NOTIFIERS)?;
        Ok(RelayNotifier { notifier, service })
    }

    /// Wakes the relay's listeners. `None`: no listener, nothing was called (no system call, no
    /// walk of iceoryx2's connections); otherwise how many listeners were woken (0 when the
    /// notification failed, e.g. a listener that just died: a relay has a safety interval).
    #[inline]
    pub fn notify(&self) -> Option<usize> {
        if self.service.dynamic_config().number_of_listeners() == 0 {
            return None;
        }
        Some(self.notifier.notify().unwrap_or(0))
    }
}

/// A relay's listener of one direction.
pub struct RelayListener {
    listener: Listener<Ipc>,
}

impl RelayListener {
    /// Listens to direction `relay` in the namespace of `session`.
    pub fn open(session: &Session, relay: Relay) -> Result<RelayListener, TransportError> {
        Ok(RelayListener {
            listener: session.listener_on(relay.service(), MAX_RELAY_NOTIFIERS)?,
        })
    }

    /// The iceoryx2 port, to attach to a wait set (it is a file descriptor on Linux).
    pub fn port(&self) -> &Listener<Ipc> {
        &self.listener
    }

    /// Blocks until a notification comes or `timeout` passes (consuming what is pending); whether
    /// one came. For a reader that is not a bridge (a benchmark's endpoints).
    pub fn wait(&self, timeout: std::time::Duration) -> bool {
        let mut got = false;
        let _ = self.listener.timed_wait(|_| got = true, timeout);
        got
    }

    /// Consumes every pending notification without blocking; whether there was one. Call it
    /// before draining the subscribers, so a publish after the drain wakes the relay again.
    pub fn take(&self) -> bool {
        let mut got = false;
        let _ = self.listener.try_wait(|_| got = true);
        got
    }
}

#[cfg(test)]
mod tests {
    use super::super::clock::monotonic_ns;
    use super::super::namespace::remove_namespace;
    use super::*;

    /// Without a listener the notifier does not call into iceoryx2 at all; with one it wakes it;
    /// when the listener goes, it stops again.
    #[test]
    fn a_relay_notifier_calls_nothing_without_a_listener() {
        let ns = format!("rl{}x{}", std::process::id(), monotonic_ns() % 100_000);
        {
            let a: Session = Session::open(&ns, "vic-test-a").unwrap();
            let b: Session = Session::open(&ns, "vic-test-b").unwrap();
            let n = RelayNotifier::open(&a, Relay::FromBoard).unwrap();
            assert_eq!(n.notify(), None, "notified without a listener");
            {
                let l = RelayListener::open(&b, Relay::FromBoard).unwrap();
                // The other direction's listener is not this service's.
                let other = RelayListener::open(&b, Relay::ToBoard).unwrap();
                assert!(!l.take());
                assert_eq!(n.notify(), Some(1));
                assert!(l.take(), "the listener was not woken");
                assert!(!l.take(), "the notification was not consumed");
                assert!(!other.take(), "the other direction was woken");
            }
            assert_eq!(n.notify(), None, "notified after the listener left");
        }
        remove_namespace(&ns);
    }
}
