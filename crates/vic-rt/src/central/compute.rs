//! What the central controller measures of its own computing, over all its trials.

use crate::transport::Percentiles;
use vic_core::replan::ReplanStats;

/// How long the central controller's periods took to compute, over all its trials.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ComputeTiming {
    /// Compute time per period [µs] (real clock, also in lockstep).
    pub compute_us: Percentiles,
    /// The budget a period's work must fit in [µs] (one planner period by default).
    pub budget_us: f64,
    /// Periods whose work took longer than the budget: they sent the previous slice again.
    pub overruns: u64,
    /// For the `replan` strategy: the time of each re-solve and what the re-solves did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub replan: Option<ReplanTiming>,
}

/// The re-solves of the `replan` strategy, over all trials.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ReplanTiming {
    /// Time of one re-solve [µs] (real clock): one per planner period.
    pub solve_us: Percentiles,
    pub stats: ReplanStats,
    /// In the background ([`super::Central::replan_in_background`]): re-solves adopted after the knot
    /// they were made for, and replanning knots skipped because a re-solve was still running.
    #[serde(default)]
    pub late: u64,
    #[serde(default)]
    pub skipped: u64,
}
