//! The fast SOOC solver's settings.

use serde::{Deserialize, Serialize};

/// Settings of [`super::SoocFastSolver`]. Defaults suit the paper's problems.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SoocFastOptions {
    /// Iteration limit (default 500: the model is not the exact Hessian, so convergence near
    /// the optimum is linear, not quadratic).
    pub max_iterations: usize,
    /// Converged when the scaled projected gradient, relative to `J`, is at most this
    /// (default 1e-6; [`crate::solver::sooc_newton::Optimality::projected_gradient`], its
    /// curvature cap taken from this solver's model, see [`super::SoocFastSolver`]) ...
    pub gradient_tolerance: f64,
    /// ... and the model's predicted decrease for its full step, relative to `J`, at most this
    /// (default 1e-9).
    pub decrease_tolerance: f64,
    /// Below this relative regularisation μ is set to 0 (default 1e-6).
    pub mu_min: f64,
    /// Give up above this μ (default 1e10).
    pub mu_max: f64,
}

impl Default for SoocFastOptions {
    fn default() -> Self {
        SoocFastOptions {
            max_iterations: 500,
            gradient_tolerance: 1e-6,
            decrease_tolerance: 1e-9,
            mu_min: 1e-6,
            mu_max: 1e10,
        }
    }
}
