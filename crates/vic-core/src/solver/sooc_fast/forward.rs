//! The moments rolled out under given controls: the true expected cost `J`.

use super::SoocProblem;
use crate::cost::Cost;
use crate::dynamics::Dynamics;
use nalgebra::DVector;

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
