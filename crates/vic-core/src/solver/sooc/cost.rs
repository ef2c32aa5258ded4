//! The expected cost of the open-loop plant in moment form.

use super::vech_pairs;
use crate::cost::{Cost, CostDerivatives, TrackingCost};
use nalgebra::DMatrix;

/// The expected cost of the open-loop plant in moment form: `ℓ(m, u) + ½ tr(ℓ_xx P)` per step and
/// `g(m_N) + ½ tr(g_xx P_N)` at the end, exact for the quadratic tracking cost of Eq. 14.
pub struct MomentCost<'a> {
    inner: &'a TrackingCost,
    n: usize,
    /// `vech` weights of `½ tr(ℓ_xx P)` (running) and `½ tr(g_xx P)` (final), per knot.
    running_weights: Vec<Vec<f64>>,
    terminal_weights: Vec<f64>,
    /// Every term is ≥ 0 ([`Cost::nonnegative`]), decided once here: the line search asks at
    /// every iteration.
    nonnegative: bool,
}

impl<'a> MomentCost<'a> {
    pub fn new(inner: &'a TrackingCost, horizon: usize) -> Self {
        let n = inner.nx;
        let nu = inner.control_weights.len();
        let mut d = CostDerivatives::new(n, nu);
        let x = vec![0.0; n];
        let u = vec![0.0; nu];
        let weights = |lxx: &DMatrix<f64>| -> Vec<f64> {
            vech_pairs(n)
                .into_iter()
                .map(|(a, b)| {
                    if a == b {
                        0.5 * lxx[(a, a)]
                    } else {
                        lxx[(a, b)]
                    }
                })
                .collect()
        };
        let running_weights: Vec<Vec<f64>> = (0..horizon)
            .map(|k| {
                inner.running_derivatives(k, &x, &u, &mut d);
                weights(&d.lxx)
            })
            .collect();
        inner.terminal_derivatives(&x, &mut d);
        let terminal_weights = weights(&d.lxx);
        // The mean's cost is the tracking cost's; the covariance's, `Σ w_ab P_ab` over
        // `vech P`, is a sum of `w_aa P_aa ≥ 0` when every weight on the diagonal is ≥ 0 and
        // every other is 0 (`P` is a covariance: its diagonal is never negative).
        let pairs = vech_pairs(n);
        let claim = |w: &[f64]| {
            pairs
                .iter()
                .zip(w)
                .all(|(&(a, b), &w)| if a == b { w >= 0.0 } else { w == 0.0 })
        };
        let nonnegative = inner.nonnegative()
            && running_weights.iter().all(|w| claim(w))
            && claim(&terminal_weights);
        MomentCost {
            inner,
            n,
            running_weights,
            terminal_weights,
            nonnegative,
        }
    }

    fn trace_term(w: &[f64], vech: &[f64]) -> f64 {
        w.iter().zip(vech).map(|(a, b)| a * b).sum()
    }
}

impl Cost for MomentCost<'_> {
    fn running(&self, k: usize, z: &[f64], u: &[f64]) -> f64 {
        let n = self.n;
        self.inner.running(k, &z[..n], u) + Self::trace_term(&self.running_weights[k], &z[n..])
    }

    fn terminal(&self, z: &[f64]) -> f64 {
        let n = self.n;
        self.inner.terminal(&z[..n]) + Self::trace_term(&self.terminal_weights, &z[n..])
    }

    fn running_derivatives(&self, k: usize, z: &[f64], u: &[f64], d: &mut CostDerivatives) {
        // The tracking cost writes the mean's block and zeros the rest of `d` (it takes a `d`
        // larger than its state): no scratch, so an iteration allocates nothing here.
        let n = self.n;
        self.inner.running_derivatives(k, &z[..n], u, d);
        d.lx.rows_mut(n, z.len() - n)
            .copy_from_slice(&self.running_weights[k]);
    }

    fn terminal_derivatives(&self, z: &[f64], d: &mut CostDerivatives) {
        let n = self.n;
        self.inner.terminal_derivatives(&z[..n], d);
        d.lx.rows_mut(n, z.len() - n)
            .copy_from_slice(&self.terminal_weights);
    }

    fn hessian_support(&self) -> Option<std::ops::Range<usize>> {
        // The mean's: the expected cost is linear in the covariance.
        self.inner.hessian_support()
    }

    fn nonnegative(&self) -> bool {
        self.nonnegative
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Exogenous;
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};

    fn tracking(w_p: f64) -> TrackingCost {
        TrackingCost {
            dof: 2,
            nx: 4,
            control_weights: vec![1e-2, 1e-2, 1e-4, 1e-4],
            w_p,
            w_v: 1e5,
            dt: 0.01,
            reference: vec![Exogenous::default()],
        }
    }

    /// The claim the line search stops rollouts on: made for the paper's cost, and then every
    /// moment state with a covariance costs ≥ 0; not made for a negative weight.
    #[test]
    fn the_expected_cost_claims_to_be_nonnegative_only_when_it_is() {
        let inner = tracking(1e6);
        let cost = MomentCost::new(&inner, 3);
        assert!(cost.nonnegative());
        let mut rng = StdRng::seed_from_u64(11);
        let mut next = || rng.random::<f64>() - 0.5;
        for _ in 0..1000 {
            // A covariance L Lᵀ, packed as vech.
            let l = DMatrix::from_fn(4, 4, |_, _| next());
            let p = &l * l.transpose();
            let mut z: Vec<f64> = (0..4).map(|_| next()).collect();
            z.extend(vech_pairs(4).into_iter().map(|(a, b)| p[(a, b)]));
            let u: Vec<f64> = (0..4).map(|_| 100.0 * next()).collect();
            assert!(cost.running(1, &z, &u) >= 0.0);
            assert!(cost.terminal(&z) >= 0.0);
        }
        let negative = tracking(-1.0);
        assert!(!MomentCost::new(&negative, 3).nonnegative());
    }
}
