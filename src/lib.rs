//! `vic`: plan and run variable-impedance control under noise, unstable force fields and feedback
//! delays (after Berret, Ivaldi, Nori & Sandini, "Stochastic optimal control with variable
//! impedance manipulators in presence of uncertainties and delayed feedback").
//!
//! This crate is the application: the command line, the daemons, the studies and the views. The
//! library is in layer crates below it, each importing only from the crates below it:
//!
//! - [`vic_core`]: the mathematics, with no I/O, clock or transport.
//! - [`vic_plan`]: scenario files, references, plan set-up, the plan file, Monte Carlo.
//! - [`vic_rt`]: the real-time side: wire protocol and iceoryx2 transport, the 1 kHz board, the
//!   50 Hz central controller, recording.
//!
//! `docs/ARCHITECTURE.md` draws the data flow and says where each equation of the paper lives.
//!
//! The application by concern; the binaries only parse their flags and call one function here:
//!
//! - [`commands`]: the `vic` command line, one module per subcommand with its flags and its
//!   `run`.
//! - [`daemons`]: the two processes, `vic-board` ([`daemons::board`]) and `vic-planner`
//!   ([`daemons::central`]) with their flags, what turns a scenario into their configuration
//!   ([`daemons::launch`]), and the daemons run as child processes ([`daemons::live`]).
//! - [`studies`]: the paper's figures ([`studies::experiment`]), delay versus stiffness over
//!   latencies ([`studies::sweep`]) and the noise identification ([`studies::identify`]).
//! - [`views`]: plots, a live run's report, the operator's snapshot of a running board and the
//!   terminal view of `vic monitor` (feature `tui`).
//! - [`bench`]: the benchmarks against the machine's own limits (`vic bench`).
//! - [`cli`]: what the three binaries share: the error convention (exit 2 for the user's input,
//!   1 for a failure) and the argument groups (`--namespace`, `--config` with `--set`, `--seed`,
//!   `--json`); [`progress`]: the progress bars on a terminal.

// Index loops read like the equations they implement; iterator chains over several arrays do not.
#![allow(clippy::needless_range_loop)]

pub mod bench;
pub mod cli;
pub mod commands;
pub mod daemons;
pub(crate) mod progress;
pub(crate) mod ranges;
pub mod studies;
pub mod views;
