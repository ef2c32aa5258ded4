//! What `converged` means for ILQG: the stop tests' values at the returned plan, beside their
//! tolerances, so that a plan file says how close to its criterion it stopped.

use super::{BackwardPass, IlqgOptions, Step};
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
    /// `max_k |l_k| / (|ū_k| + 1)` of the last backward pass; `+∞` before the first one
    /// succeeded (`null` in JSON).
    #[serde(deserialize_with = "crate::solver::infinite_if_null")]
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
    pub(crate) min_step_length: f64,
}

impl Convergence {
    /// The record before any test: no backward pass yet (an infinite feedforward step).
    pub(super) fn untested(options: &IlqgOptions, mu: f64) -> Self {
        Convergence {
            feedforward_step: f64::INFINITY,
            gradient_tolerance: options.gradient_tolerance,
            improvement: None,
            step_length: None,
            tolerance: options.tolerance,
            mu,
            trusted_mu: 0.0,
            min_step_length: options.shrink_below_step,
        }
    }

    /// Nothing left to gain at first order: the predicted improvement of an (almost) undamped
    /// Newton step is negligible against the merit. Records the test and returns its verdict.
    pub(super) fn predicted(
        &mut self,
        pass: &BackwardPass,
        mu: f64,
        trusted_mu: f64,
        merit: f64,
    ) -> bool {
        self.improvement = Some(-(pass.dv1 + pass.dv2) / merit.abs().max(1e-300));
        self.step_length = None;
        (self.mu, self.trusted_mu) = (mu, trusted_mu);
        self.improvement_met()
    }

    /// A small improvement means convergence only after a long step with little
    /// regularisation; a short, heavily damped step improves little anywhere. Records the test
    /// and returns its verdict.
    pub(super) fn achieved(&mut self, step: &Step, mu: f64, trusted_mu: f64) -> bool {
        self.improvement = Some((step.before - step.after) / step.after.abs().max(1e-300));
        self.step_length = Some(step.alpha);
        (self.mu, self.trusted_mu) = (mu, trusted_mu);
        self.improvement_met()
    }

    /// The record for a returned plan: `None` when no backward pass completed (μ passed its
    /// limit on the first one), since JSON has no infinity and a plan file must read back.
    pub(super) fn reported(self) -> Option<Self> {
        (self.feedforward_step.is_finite() && self.improvement.is_none_or(f64::is_finite))
            .then_some(self)
    }

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
