//! The solver's settings.

use serde::{Deserialize, Serialize};

/// Solver settings. Defaults suit the paper's problems.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IlqgOptions {
    /// Iteration limit (default 200).
    pub max_iterations: usize,
    /// Stop when a step improves (or is predicted to improve) the cost by less than this fraction
    /// (default 1e-6).
    pub tolerance: f64,
    /// Stop when every feedforward step `|l_k| / (|ū_k| + 1)` is below this (default 1e-6).
    pub gradient_tolerance: f64,
    /// Initial Levenberg–Marquardt regularisation μ added to `Q_uu` (default 0: exact Newton).
    pub mu_init: f64,
    /// Below this μ is set to 0 (default 1e-6).
    pub mu_min: f64,
    /// Give up above this μ (default 1e10).
    pub mu_max: f64,
    /// Raise μ after an accepted step shorter than `shrink_below_step` (default true, 0.5).
    pub damp_short_steps: bool,
    pub shrink_below_step: f64,
    /// Include the noise terms in the backward pass and the line search (default true). False
    /// gives deterministic DDP on the same plant.
    pub stochastic: bool,
    /// Controls that a deterministic solve first holds at their lower limits, then frees (default
    /// none; see [`Ilqg::try_solve`](super::Ilqg::try_solve)). For controls that act only
    /// through the deviation from the plan, such as an impedance's stiffness (paper Eq. 4).
    pub held_first: Vec<usize>,
}

impl Default for IlqgOptions {
    fn default() -> Self {
        IlqgOptions {
            max_iterations: 200,
            tolerance: 1e-6,
            gradient_tolerance: 1e-6,
            mu_init: 0.0,
            mu_min: 1e-6,
            mu_max: 1e10,
            damp_short_steps: true,
            shrink_below_step: 0.5,
            stochastic: true,
            held_first: Vec::new(),
        }
    }
}
