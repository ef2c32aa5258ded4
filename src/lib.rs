//! `vic`: plan and run variable-impedance control under noise, unstable force fields and feedback
//! delays (after Berret, Ivaldi, Nori & Sandini, "Stochastic optimal control with variable
//! impedance manipulators in presence of uncertainties and delayed feedback").
//!
//! The modules follow the paper: [`model`] (limb, actuator, field, noise) → [`dynamics`]
//! (discretisation and linearisation) → [`delay`] (state augmentation) → [`cost`] and
//! [`reference`] → [`solver`] (ILQG) → [`config`] and [`plan`] (scenarios and the `vic plan`
//! command).

// Index loops read like the equations they implement; iterator chains over several arrays do not.
#![allow(clippy::needless_range_loop)]

pub mod bench;
pub mod board;
pub mod central;
pub mod config;
pub mod cost;
pub mod daemon;
pub mod delay;
pub mod dynamics;
pub mod evaluation;
pub mod experiment;
pub mod identify;
pub mod model;
pub mod operator;
pub mod plan;
pub mod plot;
pub mod realtime;
pub mod record;
pub mod reference;
pub mod scalar;
pub mod sched;
pub mod simulation;
pub mod solver;
pub mod transport;
