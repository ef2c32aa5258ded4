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
//! What the binaries call. The binaries only parse their flags; each command is one call here:
//!
//! - [`cli`]: what the three binaries share: the error convention (exit 2 for the user's input,
//!   1 for a failure) and the argument groups (`--namespace`, `--config` with `--set`, `--seed`,
//!   `--json`).
//! - One module per command: [`plan_command`] (`vic plan`), [`simulate`], [`reproduce`]
//!   (`vic experiment`, `vic results`), [`identify_command`], [`demo`], [`operator_command`]
//!   (`vic inject`, `status`, `monitor`), [`bench_command`], [`board_daemon`] (`vic-board`) and
//!   [`central_daemon`] (`vic-planner`).
//! - The work they share: [`operator`] (inject, status, monitor), `monitor` (the live view of
//!   `vic monitor` on a terminal, with the `tui` feature), [`experiment`] (the paper's
//!   figures), [`sweep`] (delay versus stiffness over latencies), [`identify`] (noise
//!   identification), [`plot`], [`bench`], [`report`] (a live run's results) and [`launch`]
//!   (turning a scenario into the board's and the central controller's configuration), [`logging`]
//!   (the daemons' `tracing` output).

// Index loops read like the equations they implement; iterator chains over several arrays do not.
#![allow(clippy::needless_range_loop)]

pub mod bench;
pub mod bench_command;
#[cfg(feature = "zenoh")]
pub mod bridge_command;
pub mod cli;
pub mod daemons;
pub mod demo;
pub mod demo_distributed;
pub mod identify_command;
pub mod operator_command;
pub mod plan_command;
pub mod progress;
pub mod record_command;
pub mod reproduce;
pub mod simulate;
pub mod studies;
pub mod views;
