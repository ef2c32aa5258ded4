//! From a scenario file to a plan and its offline evaluation: [`scenario`] (the TOML files,
//! validated), [`reference`] (the desired movement), [`plan`] (set-up, solving, the plan file),
//! [`montecarlo`] (seeded trials on the stochastic plant) and [`evaluation`] (statistics in the
//! units a reader expects).

pub mod evaluation;
pub mod montecarlo;
pub mod plan;
pub mod reference;
pub mod scenario;
