//! What `converged` means: the first-order optimality of the controls for the box-limited
//! problem, relative to the cost, in scales that the controls' own curvature caps.

use super::SoocSolver;
use crate::solver::Bounds;
use crate::solver::boxqp::MAX_QP;
use serde::{Deserialize, Serialize};

/// The first-order optimality of a control sequence for the box-limited problem, relative to the
/// cost: what `converged` means.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Optimality {
    /// `max_{k,j} s_{k,j} |Π(∇J)_{k,j}| / |J|`: the largest first-order change of `J` from moving
    /// one control by its scale `s_{k,j}`, relative to `J`. `Π` zeroes the components at a bound
    /// whose gradient pushes out of the box (the KKT conditions). The scale is the width of the
    /// control's box where it is finite (the stiffness) and 1 (N m) where it is not (the
    /// torques), but never more than `√(2|J| / ∂²J/∂u_{k,j}²)`, the step over which the
    /// control's own curvature changes `J` by `J`: beyond it a first-order change means nothing
    /// (in the divergent field without noise an early torque's curvature is ≈ 2·10⁹ at
    /// `J ≈ 0.27`).
    pub projected_gradient: f64,
    /// `-ΔJ_pred / |J|`: the decrease the Newton model predicts for its full step; `+∞` when the
    /// last model was not the exact one (`null` in JSON).
    #[serde(deserialize_with = "crate::solver::infinite_if_null")]
    pub predicted_decrease: f64,
    /// The tolerances they were tested against.
    pub gradient_tolerance: f64,
    pub decrease_tolerance: f64,
}

impl Optimality {
    /// Whether both tests pass.
    pub fn met(&self) -> bool {
        self.projected_gradient <= self.gradient_tolerance
            && self.predicted_decrease <= self.decrease_tolerance
    }
}

impl SoocSolver {
    /// The projected gradient of the convergence test, relative to `J`. The curvature cap only
    /// lowers it, and costs a pass of its own (the Hessian's diagonal), so it is applied only
    /// when it can decide the test: after a Newton backward pass (`newton`, whose `predicted`
    /// decrease already passes) while the uncapped value fails.
    pub(super) fn projected_gradient_tested(
        &mut self,
        bounds: &Bounds,
        scale: &[f64],
        cost: f64,
        newton: bool,
        predicted: Option<(f64, f64)>,
    ) -> f64 {
        let relative = |v: f64| v / cost.abs().max(1e-300);
        let plain = relative(self.projected_gradient(bounds, scale, None));
        let decided = plain <= self.options.gradient_tolerance
            || !newton
            || predicted
                .is_none_or(|(d1, d2)| relative(-(d1 + d2)) > self.options.decrease_tolerance);
        if decided {
            return plain;
        }
        self.hessian_diagonal_pass();
        relative(self.projected_gradient(bounds, scale, Some(cost)))
    }

    /// Whether the start of a solve is near enough to an optimum for the exact model from the
    /// first step ([`super::SoocOptions::third_derivatives_below`]): its projected gradient,
    /// relative to `J` and uncapped (the first-order change of `J` from moving one control by
    /// its scale), below that fraction. A cold start from the deterministic optimum is far
    /// (0.17 on the divergent arm); the plan's tail, re-solved over the remaining movement one
    /// period later, is not (6e-6).
    pub(super) fn near_optimum(
        &self,
        problem: &super::SoocProblem,
        scale: &[f64],
        cost: f64,
    ) -> bool {
        self.options.flow_third_derivatives
            && self.projected_gradient(problem.bounds, scale, None) / cost.abs().max(1e-300)
                < self.options.third_derivatives_below
    }

    /// `max_{k,j} s_{k,j} |Π(∇J)_{k,j}|`, `Π` zeroing the components that push out of the box
    /// at a bound. With the cost `J` (after [`Self::hessian_diagonal_pass`]), each scale is
    /// capped by the control's own curvature: [`curvature_capped`].
    pub(super) fn projected_gradient(
        &self,
        bounds: &Bounds,
        scale: &[f64],
        cost: Option<f64>,
    ) -> f64 {
        let mut worst = 0.0_f64;
        for ((u, g), hd) in self.u.iter().zip(&self.grad).zip(&self.hess_diag) {
            for j in 0..self.nu {
                let gj = g[j];
                let blocked =
                    (u[j] <= bounds.lower[j] && gj > 0.0) || (u[j] >= bounds.upper[j] && gj < 0.0);
                if !blocked {
                    let s = cost.map_or(scale[j], |c| curvature_capped(scale[j], hd[j], c));
                    worst = worst.max(s * gj.abs());
                }
            }
        }
        worst
    }
}

/// Control scales: the box width where finite, else 1 (N m).
pub(super) fn control_scales(bounds: &Bounds) -> [f64; MAX_QP] {
    let mut scale = [1.0; MAX_QP];
    for (s, (lo, hi)) in scale.iter_mut().zip(bounds.lower.iter().zip(&bounds.upper)) {
        if lo.is_finite() && hi.is_finite() && hi > lo {
            *s = hi - lo;
        }
    }
    scale
}

/// A control's scale `s` capped at `√(2|J| / h)`, the step over which its own curvature
/// `h = ∂²J/∂u²` alone changes `J` by `J` (no cap where `h ≤ 0`). Beyond that step the first-order
/// change `s |g|` extrapolates a slope that the curvature has long overturned: in the divergent
/// field without noise an early torque has `h ≈ 2·10⁹` (J ≈ 0.27), so a newton-metre of it is
/// meaningless, and its gradient of 2·10⁻³ lowers `J` by at most `g² / 2h ≈ 10⁻¹⁵ J`, below
/// round-off; the uncapped test could never pass there.
fn curvature_capped(s: f64, h: f64, cost: f64) -> f64 {
    if h > 0.0 {
        s.min((2.0 * cost.abs() / h).sqrt())
    } else {
        s
    }
}
