//! The two processes and what starts them: [`board`] (`vic-board`, the 1 kHz simulated board) and
//! [`central`] (`vic-planner`, the 50 Hz central controller) with their flags, [`launch`]
//! (a scenario and a plan turned into the board's configuration and the central controller's
//! track: the only place where planning meets the real-time layer), [`live`] (the daemons as
//! child processes, for `vic demo` and `vic sweep latency --live`) and [`logging`] (their
//! `tracing` output on stderr).

pub mod board;
pub mod central;
pub mod launch;
pub(crate) mod live;
pub(crate) mod logging;
