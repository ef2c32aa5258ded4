//! The mathematics of the paper, free of I/O, clocks and transport: what both the planner and the
//! real-time board are built from.
//!
//! models (Eq. 1-8) → [`dynamics`] (Euler–Maruyama discretisation, Eq. 10) → [`delay`] (state
//! augmentation, Eq. 11-13) and [`cost`] (Eq. 14) → [`solver`] (ILQG, SOOC) → [`policy`] (the law
//! that is executed, Eq. 9 and 13).

// Index loops read like the equations they implement; iterator chains over several arrays do not.
#![allow(clippy::needless_range_loop)]

pub mod cost;
pub mod delay;
pub mod dense;
pub mod dynamics;
pub mod latency;
pub mod model;
pub mod policy;
pub mod replan;
pub mod rng;
pub mod scalar;
pub mod solver;
pub(crate) mod taylor;
pub mod wide;
