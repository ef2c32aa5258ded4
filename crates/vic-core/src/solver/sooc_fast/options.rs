//! The fast SOOC solver's settings.

use serde::{Deserialize, Serialize};

/// Settings of [`super::SoocFastSolver`]. Defaults suit the paper's problems.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SoocFastOptions {
    /// Limit of outer (Newton) iterations (default 200).
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
    /// Conjugate-gradient iterations per Newton step at most (default 60).
    pub max_cg: usize,
    /// The difference step of a Hessian-vector product: the fraction of a control's scale (its
    /// box width, else 1) that the largest entry of the direction moves (default 1e-7).
    pub fd_step: f64,
    /// Central differences of the gradient for a Hessian-vector product (two gradients, error
    /// `O(ε²)`) instead of forward ones (one gradient, error `O(ε)`) (default false).
    pub central_differences: bool,
    /// A trust region on the step in the surrogate's norm (Steihaug–Toint) rather than the
    /// Newton–CG step with a line search alone (default false).
    pub trust_region: bool,
}

impl Default for SoocFastOptions {
    fn default() -> Self {
        SoocFastOptions {
            max_iterations: 200,
            gradient_tolerance: 1e-6,
            decrease_tolerance: 1e-9,
            mu_min: 1e-6,
            mu_max: 1e10,
            max_cg: 60,
            fd_step: 1e-7,
            central_differences: false,
            trust_region: false,
        }
    }
}
