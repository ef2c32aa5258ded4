//! What one solve carries from iteration to iteration: the regularisation, which model the
//! iterations have, the tally of accepted steps and what a line search needs of its backward
//! pass.

use super::SoocOptions;

/// Levenberg–Marquardt regularisation μ (relative to each control's Gauss–Newton curvature) with
/// Tassa's multiplicative schedule.
pub(super) struct Damping {
    pub(super) mu: f64,
    pub(super) step: f64,
}

impl Damping {
    /// After a long accepted step: μ falls, to exactly 0 below `mu_min`.
    pub(super) fn decrease(&mut self, options: &SoocOptions) {
        self.step = (self.step / 2.0).min(0.5);
        self.mu *= self.step;
        if self.mu < options.mu_min {
            self.mu = 0.0;
        }
    }

    /// After a rejected step: μ rises; false when it passed `mu_max`.
    pub(super) fn increase(&mut self, options: &SoocOptions) -> bool {
        self.step = (self.step * 2.0).max(2.0);
        self.mu = (self.mu * self.step).max(options.mu_min.max(1e-3));
        self.mu <= options.mu_max
    }
}

/// Which model the iterations have.
pub(super) struct ModelState {
    /// The trajectory moved since the last expansion.
    pub(super) needs_expansion: bool,
    /// The Newton curvature of the current expansion is computed.
    pub(super) has_second_order: bool,
    /// The exact model's predicted decrease for the last accepted step (relative; ∞ when the
    /// model was not exact).
    pub(super) last_predicted: f64,
    /// No expansion yet: the next one decides whether the start is near an optimum.
    pub(super) first: bool,
    /// Iterations in a row that fell back to Gauss–Newton.
    pub(super) gauss_newton_run: usize,
    /// The Newton model includes the flow's third derivatives (the exact Hessian).
    pub(super) third: bool,
    /// The current expansion's third derivatives are the previous point's
    /// ([`SoocOptions::keep_third_derivatives`]): the model is not the exact Hessian.
    pub(super) kept: bool,
    /// The current expansion took the third derivatives anew.
    pub(super) fresh: bool,
    /// The first expansion may find its points' third derivatives in the workspace
    /// ([`super::SoocSolver::resolve_remaining`]), and at how many knots it did.
    pub(super) carry: bool,
    pub(super) carried: usize,
}

/// What the accepted steps of a solve add up to.
#[derive(Default)]
pub(super) struct Tally {
    pub(super) iterations: usize,
    /// Cost after each accepted step.
    pub(super) history: Vec<f64>,
    /// Stages convexified, over all backward passes.
    pub(super) convexified: usize,
    /// Accepted steps taken without the flow's third derivatives.
    pub(super) without_third: usize,
    /// Accepted steps taken with the previous point's third derivatives.
    pub(super) kept_third: usize,
}

/// What the line search of one iteration needs from its backward pass.
#[derive(Clone, Copy)]
pub(super) struct Phase {
    /// The model has the flow's third derivatives (or does without them by option).
    pub(super) full: bool,
    /// ... those of the previous point.
    pub(super) kept: bool,
    /// The model's first- and second-order predicted changes of `J` for a full step.
    pub(super) predicted: (f64, f64),
    /// The model's predicted decrease relative to `J` (infinite without the exact model).
    pub(super) predicted_decrease: f64,
}
