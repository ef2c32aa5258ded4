//! `vic`: plan and run variable-impedance control under noise, unstable force fields and feedback
//! delays (after Berret, Ivaldi, Nori & Sandini, "Stochastic optimal control with variable
//! impedance manipulators in presence of uncertainties and delayed feedback").
//!
//! The library is four layers; each imports only from the layers below it:
//!
//! - [`core`]: the mathematics, with no I/O, clock or transport: plant models (limb, actuator,
//!   field, noise), discretisation, the delay and mean/covariance transforms, the cost, the one
//!   [`core::policy::Policy`] that is executed, and the solvers (ILQG, SOOC).
//! - [`planning`]: scenario files, references, plan set-up and the plan file format, Monte Carlo
//!   execution and its evaluation.
//! - [`rt`] (feature `rt`): the real-time side: wire protocol and iceoryx2 transport, periodic loop
//!   and scheduling, the 1 kHz board, the 50 Hz central controller, recording.
//! - [`tools`] (features `rt` and `plot`): what the binaries call: operator commands, the demo,
//!   experiments, noise identification, plots and benchmarks.
//!
//! `docs/ARCHITECTURE.md` draws the data flow and says where each equation of the paper lives.

// Index loops read like the equations they implement; iterator chains over several arrays do not.
#![allow(clippy::needless_range_loop)]

pub mod core;
pub mod planning;
#[cfg(feature = "rt")]
pub mod rt;
#[cfg(all(feature = "rt", feature = "plot"))]
pub mod tools;
