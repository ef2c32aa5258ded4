//! The two-rate real-time controller: [`transport`] (the wire protocol, the shared clock,
//! namespaces and the iceoryx2 ports of each role), [`realtime`] (clock, absolute-deadline loop,
//! histograms), [`sched`] (OS scheduling, memory locking), [`board`] (the 1 kHz impedance law,
//! Eq. 4, against a simulated plant, and its live runner), [`central`] (the 50 Hz controller that
//! streams a [`vic_core::policy::Policy`]), [`record`] (lossless tick logs) and [`daemon`] (child
//! processes). Nothing here knows about scenario files: callers hand in a
//! [`board::BoardConfig`], a core plant and a policy.

// Index loops read like the equations they implement; iterator chains over several arrays do not.
#![allow(clippy::needless_range_loop)]

pub mod board;
#[cfg(feature = "zenoh")]
pub mod bridge;
pub mod central;
pub mod daemon;
pub mod realtime;
pub mod record;
pub mod sched;
pub mod transport;
