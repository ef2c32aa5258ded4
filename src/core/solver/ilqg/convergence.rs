//! What `converged` means for ILQG: the stop tests' values at the returned plan, beside their
//! tolerances, so that a plan file says how close to its criterion it stopped.

use serde::{Deserialize, Serialize};

/// The values the stop tests of the last iteration compared against their tolerances. A solve
/// converged when either test holds ([`Convergence::met`]):
/// - **SmallGradient**: the feedforward step of the last backward pass, `max_k |l_k| / (|ū_k| +
///   1)` (zero at a first-order optimum projected onto the limits, since clamped components get
///   `l = 0`), is below `gradient_tolerance`;
/// - **SmallImprovement**: the relative improvement is below `tolerance` while the model was
///   trusted: regularisation `μ ≤ trusted_mu` (10⁻³ × the mean diagonal of the value Hessian
///   `S_0`) and, for the improvement of an accepted step, a step length `α ≥ min_step_length`
///   (a short, heavily damped step improves little anywhere).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Convergence {
    /// `max_k |l_k| / (|ū_k| + 1)` of the last backward pass.
    pub feedforward_step: f64,
    pub gradient_tolerance: f64,
    /// The relative improvement tested last: predicted for a full Newton step by the last
    /// backward pass, `−(dv1 + dv2) / |merit|` (then `step_length` is `None`), or achieved by the
    /// last accepted step, `(before − after) / |after|`. `None` when no improvement was tested
    /// (the first backward pass already met the gradient test, or failed).
    pub improvement: Option<f64>,
    /// The length α of the accepted step whose improvement `improvement` is.
    pub step_length: Option<f64>,
    pub tolerance: f64,
    /// The regularisation μ in force at that test, and the largest μ at which the local model
    /// is trusted for a verdict.
    pub mu: f64,
    pub trusted_mu: f64,
    /// The shortest step whose improvement counts (`shrink_below_step`).
    pub min_step_length: f64,
}

impl Convergence {
    /// Whether the gradient test or the improvement test holds.
    pub fn met(&self) -> bool {
        self.gradient_met() || self.improvement_met()
    }

    /// The feedforward step is below its tolerance.
    pub fn gradient_met(&self) -> bool {
        self.feedforward_step < self.gradient_tolerance
    }

    /// A trusted improvement is below its tolerance.
    pub fn improvement_met(&self) -> bool {
        let long = self.step_length.is_none_or(|a| a >= self.min_step_length);
        self.improvement.is_some_and(|i| i < self.tolerance) && long && self.mu <= self.trusted_mu
    }
}
