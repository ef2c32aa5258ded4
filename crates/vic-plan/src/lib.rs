//! From a scenario file to a plan and its offline evaluation: [`scenario`] (the TOML files,
//! validated), [`reference`] (the desired movement), [`setup`] (the Eq. 10 model, the Eq. 14 cost
//! and the warm start), [`plan`] (solving with a [`method`]), [`plan_file`] (what `vic plan`
//! writes and the other commands read), [`montecarlo`] (seeded trials on the stochastic plant) and
//! [`evaluation`] (statistics in the [`unit`] a reader expects); [`strategy`] ties a central
//! strategy and its latency to the plan it needs and the law that executes it.

// Index loops read like the equations they implement; iterator chains over several arrays do not.
#![allow(clippy::needless_range_loop)]

pub mod bounded_read;
pub mod evaluation;
pub mod method;
pub mod montecarlo;
pub mod plan;
pub mod plan_file;
pub mod prediction;
pub mod receding;
pub(crate) mod reference;
pub mod scenario;
pub mod setup;
pub mod strategy;
pub mod unit;
