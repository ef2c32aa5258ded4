//! The studies the commands run and report: [`experiment`] (the paper's figures and the claims
//! docs/RESULTS.md checks), [`sweep`] (the final error against the feedback latency, per
//! strategy) and [`identify`] (the paper's identification of the joint's torque noise, Sec.
//! III-B).

pub mod experiment;
pub mod identify;
pub mod sweep;
