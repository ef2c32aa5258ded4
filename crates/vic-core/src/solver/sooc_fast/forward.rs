//! The forward pass: the moments rolled out under the step's policy (feedback on the mean), and
//! the backtracking line search on the true expected cost `J`.

use super::{SoocFastSolver, SoocProblem};
use crate::cost::Cost;
use crate::dynamics::Dynamics;
use nalgebra::DVector;

impl SoocFastSolver {
    /// Backtracking line search on the true `J` from `cost`: the first `α` (halving from 1, 12
    /// tries) whose cost decreases by at least a tenth of the prediction `α dv1 + α² dv2`. The
    /// candidate holds that rollout; `(J, α)`.
    pub(super) fn line_search(
        &mut self,
        problem: &SoocProblem,
        cost: f64,
        dv1: f64,
        dv2: f64,
    ) -> Option<(f64, f64)> {
        let mut alpha = 1.0;
        for _ in 0..12 {
            let expected = alpha * dv1 + alpha * alpha * dv2;
            let c = self.forward(problem, alpha);
            let actual = c - cost;
            if c.is_finite() && actual < 0.0 && (expected >= 0.0 || actual <= 0.1 * expected) {
                return Some((c, alpha));
            }
            alpha *= 0.5;
        }
        None
    }

    /// Rolls out `u + α k + K (m' − m)` (clamped) into the candidate; its `J` (∞ if the moments
    /// blow up).
    fn forward(&mut self, problem: &SoocProblem, alpha: f64) -> f64 {
        let (n, h) = (self.n, self.horizon);
        self.cand_z[0].copy_from(&self.z[0]);
        let mut cost = 0.0;
        for k in 0..h {
            self.dm.copy_from(&self.cand_z[k].rows(0, n));
            self.dm -= &self.z[k].rows(0, n);
            let u = &mut self.cand_u[k];
            u.copy_from(&self.u[k]);
            u.axpy(alpha, &self.ff[k], 1.0);
            u.gemv(1.0, &self.gains[k], &self.dm, 1.0);
            problem.bounds.clamp(u.as_mut_slice());
            let (head, tail) = self.cand_z.split_at_mut(k + 1);
            cost += problem.cost.running(k, head[k].as_slice(), u.as_slice());
            problem
                .dynamics
                .step(k, head[k].as_slice(), u.as_slice(), tail[0].as_mut_slice());
            if !cost.is_finite() || tail[0].iter().any(|v| !v.is_finite()) {
                return f64::INFINITY;
            }
        }
        cost + problem.cost.terminal(self.cand_z[h].as_slice())
    }
}

/// Rolls `u` out from `z[0]`: the true expected cost (∞ if the moments blow up).
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
