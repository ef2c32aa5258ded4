//! Costs: the discrete running cost `ℓ_k(x, u)` (already multiplied by Δ) and the final cost
//! `g(x)`, with their derivatives.

use crate::core::dense::zero;
use crate::core::model::Exogenous;
use nalgebra::{DMatrix, DVector};

/// First and second derivatives of a cost term at one knot.
#[derive(Debug, Clone)]
pub struct CostDerivatives {
    pub lx: DVector<f64>,
    pub lu: DVector<f64>,
    pub lxx: DMatrix<f64>,
    pub luu: DMatrix<f64>,
    /// `∂²ℓ/∂u∂x` (m×n).
    pub lux: DMatrix<f64>,
}

impl CostDerivatives {
    pub fn new(nx: usize, nu: usize) -> Self {
        CostDerivatives {
            lx: DVector::zeros(nx),
            lu: DVector::zeros(nu),
            lxx: DMatrix::zeros(nx, nx),
            luu: DMatrix::zeros(nu, nu),
            lux: DMatrix::zeros(nu, nx),
        }
    }
}

/// An additive cost over a horizon: `Σ_k ℓ_k(x_k, u_k) + g(x_N)`.
pub trait Cost: Send + Sync {
    /// Running cost of knot `k` (for a continuous integrand, Δ times it).
    fn running(&self, k: usize, x: &[f64], u: &[f64]) -> f64;
    /// Final cost.
    fn terminal(&self, x: &[f64]) -> f64;
    /// Derivatives of the running cost (overwrites every field of `d`).
    fn running_derivatives(&self, k: usize, x: &[f64], u: &[f64], d: &mut CostDerivatives);
    /// Derivatives of the final cost (overwrites `lx` and `lxx`).
    fn terminal_derivatives(&self, x: &[f64], d: &mut CostDerivatives);
    /// Whether every running and final cost is ≥ 0 wherever it is evaluated: then a partial sum
    /// along a rollout bounds its total from below, and the line search may stop rolling out a
    /// step once it costs more than the nominal (default: not known).
    fn nonnegative(&self) -> bool {
        false
    }
}

/// Paper Eq. 14: `∫ (uᵀ W u + w_p |q − q_d|² + w_v |q' − q_d'|²) dt + w_p |q(T) − q_d(T)|² +
/// w_v |q'(T)|²`, discretised with the rectangle rule on the time grid.
#[derive(Debug, Clone)]
pub struct TrackingCost {
    /// Number of joints.
    pub dof: usize,
    /// State dimension (the joint angles and velocities come first).
    pub nx: usize,
    /// Diagonal of `W`, one weight per control.
    pub control_weights: Vec<f64>,
    /// Position weight `w_p`.
    pub w_p: f64,
    /// Velocity weight `w_v`.
    pub w_v: f64,
    /// Time step Δ [s].
    pub dt: f64,
    /// Reference at each knot `0..=N` (the final knot is the target).
    pub reference: Vec<Exogenous>,
}

impl TrackingCost {
    fn target(&self, k: usize) -> &Exogenous {
        &self.reference[k.min(self.reference.len() - 1)]
    }
}

impl Cost for TrackingCost {
    fn running(&self, k: usize, x: &[f64], u: &[f64]) -> f64 {
        let r = self.target(k);
        let n = self.dof;
        let mut l: f64 = u
            .iter()
            .zip(&self.control_weights)
            .map(|(u, w)| w * u * u)
            .sum();
        for i in 0..n {
            l += self.w_p * (x[i] - r.q_d[i]).powi(2) + self.w_v * (x[n + i] - r.qd_d[i]).powi(2);
        }
        self.dt * l
    }

    fn terminal(&self, x: &[f64]) -> f64 {
        let r = self.reference.last().expect("reference is not empty");
        (0..self.dof)
            .map(|i| self.w_p * (x[i] - r.q_d[i]).powi(2) + self.w_v * x[self.dof + i].powi(2))
            .sum()
    }

    /// `d` may be larger than the state (a moment state, its mean first): the entries beyond
    /// the state are zeros, the derivatives of the mean's part of the expected cost.
    fn running_derivatives(&self, k: usize, x: &[f64], u: &[f64], d: &mut CostDerivatives) {
        let r = self.target(k);
        let n = self.dof;
        zero(&mut d.lx);
        zero(&mut d.lxx);
        zero(&mut d.luu);
        zero(&mut d.lux);
        for i in 0..n {
            d.lx[i] = 2.0 * self.dt * self.w_p * (x[i] - r.q_d[i]);
            d.lx[n + i] = 2.0 * self.dt * self.w_v * (x[n + i] - r.qd_d[i]);
            d.lxx[(i, i)] = 2.0 * self.dt * self.w_p;
            d.lxx[(n + i, n + i)] = 2.0 * self.dt * self.w_v;
        }
        for (j, w) in self.control_weights.iter().enumerate() {
            d.lu[j] = 2.0 * self.dt * w * u[j];
            d.luu[(j, j)] = 2.0 * self.dt * w;
        }
    }

    fn nonnegative(&self) -> bool {
        // A weighted sum of squares, the running part times Δ.
        self.dt >= 0.0
            && self.w_p >= 0.0
            && self.w_v >= 0.0
            && self.control_weights.iter().all(|w| *w >= 0.0)
    }

    /// `d` may be larger than the state, as for [`Cost::running_derivatives`].
    fn terminal_derivatives(&self, x: &[f64], d: &mut CostDerivatives) {
        let r = self.reference.last().expect("reference is not empty");
        let n = self.dof;
        zero(&mut d.lx);
        zero(&mut d.lxx);
        for i in 0..n {
            d.lx[i] = 2.0 * self.w_p * (x[i] - r.q_d[i]);
            d.lx[n + i] = 2.0 * self.w_v * x[n + i];
            d.lxx[(i, i)] = 2.0 * self.w_p;
            d.lxx[(n + i, n + i)] = 2.0 * self.w_v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cost(w_p: f64, w_u: f64) -> TrackingCost {
        TrackingCost {
            dof: 1,
            nx: 2,
            control_weights: vec![w_u],
            w_p,
            w_v: 1.0,
            dt: 0.01,
            reference: vec![Exogenous::default()],
        }
    }

    #[test]
    fn a_negative_weight_or_step_makes_no_claim_of_a_nonnegative_cost() {
        assert!(cost(1.0, 1.0).nonnegative());
        assert!(cost(0.0, 0.0).nonnegative());
        assert!(!cost(-1.0, 1.0).nonnegative());
        assert!(!cost(1.0, -1e-9).nonnegative());
        assert!(!cost(f64::NAN, 1.0).nonnegative());
        let backwards = TrackingCost {
            dt: -0.01,
            ..cost(1.0, 1.0)
        };
        assert!(!backwards.nonnegative());
    }
}
