//! The forward pass: rolling the moment dynamics out under the step's policy, and the
//! backtracking line search on the true expected cost `J`.

use super::{SoocProblem, SoocSolver};
use crate::cost::Cost;
use crate::dynamics::Dynamics;
use nalgebra::DVector;

impl SoocSolver {
    /// Backtracking line search on the true cost from `cost`: the first step length `α`
    /// (halving from 1, 12 tries) whose cost decreases by at least a tenth of the model's
    /// prediction `α dv1 + α² dv2` (any decrease when the model predicts none). The candidate
    /// holds that rollout; `(J, α)`.
    ///
    /// When the cost is never negative ([`Cost::nonnegative`]), a rollout's partial sum bounds
    /// its total from below, so a rollout stops as soon as its partial sum passes the most the
    /// step could cost and still be accepted: the verdict is the same, and the steps taken are
    /// the same to the bit. Far from the optimum the backward pass can predict decreases many
    /// times `J` (its value recursion grows through the unstable field), which no nonnegative
    /// cost can realise: such a step then costs one knot of a rollout per `α`, not a whole
    /// rollout.
    pub(super) fn line_search(
        &mut self,
        problem: &SoocProblem,
        cost: f64,
        dv1: f64,
        dv2: f64,
    ) -> Option<(f64, f64)> {
        let bounded = problem.cost.nonnegative();
        let mut alpha = 1.0;
        for _ in 0..12 {
            let expected = alpha * dv1 + alpha * alpha * dv2;
            let limit = if bounded {
                acceptance_limit(cost, expected)
            } else {
                f64::INFINITY
            };
            let c = self.forward(problem, alpha, limit);
            if accepted(c, cost, expected) {
                return Some((c, alpha));
            }
            alpha *= 0.5;
        }
        None
    }

    /// Rolls out `u + α k + K (z' − z)` (clamped) into the candidate; its cost, or ∞ as soon as
    /// the running sum passes `limit` (see [`Self::line_search`]).
    fn forward(&mut self, problem: &SoocProblem, alpha: f64, limit: f64) -> f64 {
        let h = self.horizon;
        self.cand_z[0].copy_from(&self.z[0]);
        let mut cost = 0.0;
        for k in 0..h {
            self.dz.copy_from(&self.cand_z[k]);
            self.dz -= &self.z[k];
            let u = &mut self.cand_u[k];
            u.copy_from(&self.u[k]);
            u.axpy(alpha, &self.ff[k], 1.0);
            u.gemv(1.0, &self.gains[k], &self.dz, 1.0);
            problem.bounds.clamp(u.as_mut_slice());
            let (head, tail) = self.cand_z.split_at_mut(k + 1);
            cost += problem.cost.running(k, head[k].as_slice(), u.as_slice());
            problem
                .dynamics
                .step(k, head[k].as_slice(), u.as_slice(), tail[0].as_mut_slice());
            if !cost.is_finite() || cost > limit || tail[0].iter().any(|v| !v.is_finite()) {
                return f64::INFINITY;
            }
        }
        cost + problem.cost.terminal(self.cand_z[h].as_slice())
    }
}

/// Rolls `u` out from `z[0]`; the cost (infinite if the moments blow up).
pub(super) fn rollout(problem: &SoocProblem, z: &mut [DVector<f64>], u: &[DVector<f64>]) -> f64 {
    let mut cost = 0.0;
    for (k, uk) in u.iter().enumerate() {
        let (head, tail) = z.split_at_mut(k + 1);
        cost += problem.cost.running(k, head[k].as_slice(), uk.as_slice());
        problem
            .dynamics
            .step(k, head[k].as_slice(), uk.as_slice(), tail[0].as_mut_slice());
        if !cost.is_finite() || tail[0].iter().any(|v| !v.is_finite()) {
            return f64::INFINITY;
        }
    }
    cost + problem.cost.terminal(z[u.len()].as_slice())
}

/// The line search's test: the rollout's cost `c` from `cost` decreases, by at least a tenth of
/// the model's prediction `expected` when that is a decrease.
fn accepted(c: f64, cost: f64, expected: f64) -> bool {
    let actual = c - cost;
    c.is_finite() && actual < 0.0 && (expected >= 0.0 || actual <= 0.1 * expected)
}

/// The largest partial sum of a rollout's nonnegative cost at which the line search could still
/// accept it from `cost`, with the model's prediction `expected`: a total `c` is accepted only
/// if `c − cost < 0` and, when `expected < 0`, `c − cost ≤ expected / 10`. Floating-point sums of
/// nonnegative terms never decrease, so a partial sum above this rules the rollout out; the
/// margin (1e-9 of `J`) covers the rounding of the covariance's diagonal near 0.
fn acceptance_limit(cost: f64, expected: f64) -> f64 {
    let margin = 1e-9 * cost.abs();
    if expected < 0.0 {
        cost + 0.1 * expected + margin
    } else {
        cost + margin
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};

    /// Every total above the limit is rejected, so a rollout stopped there loses nothing; and the
    /// limit is not looser than the margin needs (a total a little below it is accepted).
    #[test]
    fn a_rollout_stopped_above_the_limit_would_have_been_rejected() {
        let mut rng = StdRng::seed_from_u64(7);
        let mut next = || rng.random::<f64>();
        let mut tight = 0;
        for _ in 0..100_000 {
            let cost = 10f64.powf(12.0 * next() - 4.0);
            // Predictions from a large increase to a decrease of many times the cost.
            let expected = cost * (40.0 * next() - 30.0) * 10f64.powf(3.0 * next() - 2.0);
            let limit = acceptance_limit(cost, expected);
            for above in [
                limit,
                limit * (1.0 + 1e-15),
                limit + cost * next(),
                f64::INFINITY,
            ] {
                if above > limit {
                    assert!(
                        !accepted(above, cost, expected),
                        "{cost} {expected} {above}"
                    );
                }
            }
            let below = limit - 2e-9 * cost;
            if below >= 0.0 && (expected >= 0.0 || expected > -10.0 * cost) {
                assert!(accepted(below, cost, expected), "{cost} {expected} {below}");
                tight += 1;
            }
        }
        assert!(
            tight > 10_000,
            "the acceptable side was tried {tight} times"
        );
    }
}
