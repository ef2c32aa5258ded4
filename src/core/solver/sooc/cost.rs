//! The expected cost of the open-loop plant in moment form.

use super::vech_pairs;
use crate::core::cost::{Cost, CostDerivatives, TrackingCost};
use crate::core::dense::zero;
use nalgebra::DMatrix;

/// The expected cost of the open-loop plant in moment form: `ℓ(m, u) + ½ tr(ℓ_xx P)` per step and
/// `g(m_N) + ½ tr(g_xx P_N)` at the end, exact for the quadratic tracking cost of Eq. 14.
pub struct MomentCost<'a> {
    inner: &'a TrackingCost,
    n: usize,
    /// `vech` weights of `½ tr(ℓ_xx P)` (running) and `½ tr(g_xx P)` (final), per knot.
    running_weights: Vec<Vec<f64>>,
    terminal_weights: Vec<f64>,
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
        let running_weights = (0..horizon)
            .map(|k| {
                inner.running_derivatives(k, &x, &u, &mut d);
                weights(&d.lxx)
            })
            .collect();
        inner.terminal_derivatives(&x, &mut d);
        let terminal_weights = weights(&d.lxx);
        MomentCost {
            inner,
            n,
            running_weights,
            terminal_weights,
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
        let n = self.n;
        let mut inner = CostDerivatives::new(n, u.len());
        self.inner.running_derivatives(k, &z[..n], u, &mut inner);
        zero(&mut d.lx);
        zero(&mut d.lxx);
        zero(&mut d.lux);
        d.lx.rows_mut(0, n).copy_from(&inner.lx);
        d.lx.rows_mut(n, z.len() - n)
            .copy_from_slice(&self.running_weights[k]);
        d.lxx.view_mut((0, 0), (n, n)).copy_from(&inner.lxx);
        d.lux.view_mut((0, 0), (u.len(), n)).copy_from(&inner.lux);
        d.lu.copy_from(&inner.lu);
        d.luu.copy_from(&inner.luu);
    }

    fn terminal_derivatives(&self, z: &[f64], d: &mut CostDerivatives) {
        let n = self.n;
        let mut inner = CostDerivatives::new(n, d.lu.len());
        self.inner.terminal_derivatives(&z[..n], &mut inner);
        zero(&mut d.lx);
        zero(&mut d.lxx);
        d.lx.rows_mut(0, n).copy_from(&inner.lx);
        d.lx.rows_mut(n, z.len() - n)
            .copy_from_slice(&self.terminal_weights);
        d.lxx.view_mut((0, 0), (n, n)).copy_from(&inner.lxx);
    }
}
