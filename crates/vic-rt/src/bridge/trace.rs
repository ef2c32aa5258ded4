//! Per-hop time stamps of the bridge, for `vic bench bridge --trace`: where a message's one-way
//! time goes (the sending bridge's wake-up, its Zenoh put, the receiving callback, the local
//! publish from that callback). Off by default: then a mark is one relaxed atomic load and nothing else — no clock
//! read, no allocation, no I/O on the forwarding path.
//!
//! A mark keeps only the *last* time each point was passed, per side, so it describes one
//! message at a time: the benchmark's ping–pong has one message in flight and reads the marks
//! after each round trip. With several messages in flight the marks mix them.

use super::Side;
use crate::transport::monotonic_ns;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// The points a bridge passes, on each side.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Point {
    /// The bridge's thread woke and found a local publisher's relay notification.
    LocalWoke,
    /// A local message was put on the link (the put returned).
    Put,
    /// A Zenoh callback of a subscription on the link was entered.
    Callback,
    /// A message from the link was published into iceoryx2 (and its listeners notified).
    Published,
}

const POINTS: usize = 4;

static ENABLED: AtomicBool = AtomicBool::new(false);
static AT: [AtomicU64; 2 * POINTS] = [const { AtomicU64::new(0) }; 2 * POINTS];

fn slot(side: Side, p: Point) -> usize {
    2 * p as usize + (side == Side::Central) as usize
}

/// Turns the marks on or off (and clears them). Process-wide: every bridge of the process.
pub fn enable(on: bool) {
    clear();
    ENABLED.store(on, Ordering::Relaxed);
}

/// Forgets the marks so far.
pub fn clear() {
    AT.iter().for_each(|a| a.store(0, Ordering::Relaxed));
}

/// Notes that the bridge on `side` passed `p` now (when marks are on).
#[inline]
pub fn mark(side: Side, p: Point) {
    if ENABLED.load(Ordering::Relaxed) {
        AT[slot(side, p)].store(monotonic_ns(), Ordering::Relaxed);
    }
}

/// When the bridge on `side` last passed `p` (monotonic ns), 0 if not since the last clear.
pub fn at(side: Side, p: Point) -> u64 {
    AT[slot(side, p)].load(Ordering::Relaxed)
}
