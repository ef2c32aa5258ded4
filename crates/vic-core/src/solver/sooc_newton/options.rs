//! The stagewise Newton solver's settings and why it stopped.

use super::Indefinite;
use serde::{Deserialize, Serialize};

/// Settings of the stagewise Newton solver. Defaults suit the paper's problems.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SoocOptions {
    /// Iteration limit (default 100; a converging solve needs 5–30).
    pub max_iterations: usize,
    /// Converged when the scaled projected gradient, relative to `J`, is at most this
    /// (default 1e-6; see [`super::Optimality::projected_gradient`]).
    pub gradient_tolerance: f64,
    /// ... and the Newton step's predicted decrease, relative to `J`, at most this (default 1e-9).
    pub decrease_tolerance: f64,
    /// Below this relative regularisation μ is set to 0 (default 1e-6).
    pub mu_min: f64,
    /// Give up above this μ (default 1e10).
    pub mu_max: f64,
    /// Whether the Newton model includes the third derivatives of the flow (default true: the
    /// exact Hessian, which the convergence to a stated criterion needs; see
    /// [`crate::solver::sooc::MomentDynamics::second_order`]). They are about two thirds
    /// of a Newton iteration on the arm (third derivatives along 116 directions per knot, eight
    /// to a flow; `docs/BENCHMARKS.md`, "Why targets are missed"). Without them the model keeps
    /// the curvature that makes stiffness worth buying (the covariance's `A P Aᵀ` is quadratic in
    /// the controls through the flow's *second* derivatives) and drops the costate-weighted
    /// change of `∂A/∂v` along `v`: a model that is no longer the exact Hessian, so far from the
    /// optimum its steps are as good, near it convergence slows to linear (on the divergent arm
    /// hundreds of such iterations do not reach the tolerances that a few dozen exact ones do).
    /// What a few warm-started iterations per re-solve need (the `replan` strategy), not a plan.
    pub flow_third_derivatives: bool,
    /// With `flow_third_derivatives`: the Newton model leaves them out while the last accepted
    /// step gained more than this fraction of `J`, and adds them for good once a step gains
    /// less (default ∞: always). Far from the optimum the model without them steps as well at
    /// about a third of the cost; near it only the exact Hessian converges fast, and only a pass with
    /// it tests the predicted decrease (so `Converged` still means the exact model's). Before the
    /// first step, the start's projected gradient relative to `J` stands in for the gain: a warm
    /// start below this fraction (the plan's tail over the remaining movement) has the exact
    /// model from the first step, where the Gauss–Newton one is worst.
    pub third_derivatives_below: f64,
    /// With the third derivatives in the model: every other Newton step keeps those of the
    /// previous point instead of taking them anew (default false). They are most of a Newton
    /// step's cost (their 15 flows of eight lanes per knot against the second derivatives' three
    /// on the arm); the part of the Hessian they give is then off by O(|step|), so the model
    /// is exact only up to the step's own size and converges superlinearly, not quadratically.
    /// A step on kept derivatives is never an exact one: it cannot declare convergence, and when
    /// it finds no descent at any μ the derivatives are taken anew. They are not kept after an
    /// exact step that predicted less than a thousand times `decrease_tolerance`: the next point
    /// is then likely the optimum, which only a fresh exact model can certify. It pays on the
    /// arms in the divergent field (fewer or as many steps, a third of them cheap) and not where
    /// the third derivatives are in from the first step; keeping them two or three steps in a
    /// row does not pay (`docs/BENCHMARKS.md`, "Approaches that did not pay").
    pub keep_third_derivatives: bool,
    /// What a backward pass does with a stage whose Newton `Q_uu` is not positive definite
    /// (default [`Indefinite::Regularize`]).
    pub indefinite: Indefinite,
}

impl Default for SoocOptions {
    fn default() -> Self {
        SoocOptions {
            max_iterations: 100,
            gradient_tolerance: 1e-6,
            decrease_tolerance: 1e-9,
            mu_min: 1e-6,
            mu_max: 1e10,
            flow_third_derivatives: true,
            third_derivatives_below: f64::INFINITY,
            keep_third_derivatives: false,
            indefinite: Indefinite::Regularize,
        }
    }
}

/// Why the solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SoocStop {
    /// Both tests of [`super::Optimality`] passed.
    Converged,
    /// The iteration limit was reached.
    MaxIterations,
    /// Regularisation grew past its limit without a descent step.
    RegularizationLimit,
}
