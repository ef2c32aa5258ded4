//! The relay notification the board's ports add to every publish and event (the bridge's wake-up,
//! `vic_rt::transport::relay`) allocates nothing: with no bridge listening, and with one that has
//! connected (the first notification after a listener joins connects to it, once). Measured on
//! `BoardPorts::notify`, which is the board's event notification plus the relay's, beside a
//! listener of the board's events (the publishes themselves are counted in tests/board_alloc.rs:
//! iceoryx2 0.10 allocates the shared state of every loaned sample, which vic's service recycles,
//! `vic_rt::transport::recycled`).

use crate::common;

use common::alloc::allocations;
use common::daemons::unique_namespace;
use vic_rt::transport::relay::{Relay, RelayListener};
use vic_rt::transport::{BoardEvent, BoardPorts, CentralPorts, Header, StateMsg, Telemetry};

#[test]
fn board_notifications_do_not_allocate_with_or_without_a_relay_listener() {
    let ns = unique_namespace("ral");
    {
        let board = BoardPorts::open(&ns).unwrap();
        let central = CentralPorts::open(&ns).unwrap();
        // What one tick publishes; the notifications counted alone.
        let tick = |seq: u64| {
            let s = StateMsg {
                header: Header::new(seq, 0),
                ..Default::default()
            };
            let _ = board.publish_state(&s);
            let before = allocations();
            board.notify(BoardEvent::Applied);
            let mut n = allocations() - before;
            if seq.is_multiple_of(100) {
                let _ = board.publish_telemetry(&Telemetry::default());
                let before = allocations();
                board.notify(BoardEvent::Telemetry);
                n += allocations() - before;
            }
            n
        };
        let drain = || while central.latest_state().is_some() {};
        for seq in 1..=10 {
            tick(seq);
        }
        drain();
        let without: u64 = (11..=1000).map(tick).sum();
        assert_eq!(
            without, 0,
            "allocations in 990 ticks without a relay listener"
        );

        let relay = RelayListener::open(central.session(), Relay::FromBoard).unwrap();
        // The first notification connects to the new listener.
        tick(1001);
        assert!(relay.take(), "the relay listener was not notified");
        let mut with = 0;
        let mut woken = 0;
        for seq in 1002..=2000 {
            with += tick(seq);
            woken += relay.take() as u64;
            drain();
        }
        assert_eq!(with, 0, "allocations in 999 ticks with a relay listener");
        assert!(
            woken > 900,
            "the listener was woken {woken} times in 999 ticks"
        );
    }
    vic_rt::transport::remove_namespace(&ns);
}
