//! Costs: the discrete running cost `ℓ_k(x, u)` (already multiplied by Δ) and the final cost
//! `g(x)`, with their derivatives.

use crate::dense::zero;
use crate::model::Exogenous;
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
    /// [`Cost::running_derivatives`] into a `d` that holds this cost's running derivatives at
    /// knot `k` from an earlier call (at another state and control), with the same result. A
    /// cost whose derivatives are zero outside fixed entries writes only those: the tracking
    /// cost's Hessian is a diagonal over the joints' angles and velocities, and clearing it
    /// whole at every knot is a pass over a 42×42 matrix per knot on the delayed plant.
    /// The solvers call it where they ask the plant to refill a linearisation (`refill` of
    /// [`crate::dynamics::Dynamics::linearize_with`]).
    /// Default: [`Cost::running_derivatives`].
    fn running_derivatives_again(&self, k: usize, x: &[f64], u: &[f64], d: &mut CostDerivatives) {
        self.running_derivatives(k, x, u, d);
    }
    /// Derivatives of the final cost (overwrites `lx` and `lxx`).
    fn terminal_derivatives(&self, x: &[f64], d: &mut CostDerivatives);
    /// The state components where the Hessian `l_xx` can be nonzero, if the cost knows: its
    /// entries outside these rows and columns are `+0` at every knot and at the end. The
    /// backward pass then takes those columns of `l_xx` as zero without reading them (on the
    /// 42-state delayed plant, whose cost reads the plant's 2 components, the others would be a
    /// stream of 14 KB per knot from memory). Default: `None` (any).
    fn hessian_support(&self) -> Option<std::ops::Range<usize>> {
        None
    }
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
        zero(&mut d.lx);
        zero(&mut d.lxx);
        zero(&mut d.luu);
        zero(&mut d.lux);
        self.running_derivatives_again(k, x, u, d);
    }

    /// Writes the entries that can be nonzero (the others are those `running_derivatives`
    /// cleared).
    fn running_derivatives_again(&self, k: usize, x: &[f64], u: &[f64], d: &mut CostDerivatives) {
        let r = self.target(k);
        let n = self.dof;
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

    fn hessian_support(&self) -> Option<std::ops::Range<usize>> {
        // The joints' angles and velocities: the derivatives clear every other entry.
        Some(0..2 * self.dof)
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

    /// Derivatives refilled over another knot's (`running_derivatives_again`) are the fresh
    /// ones to the bit, for a two-joint cost on a larger (augmented) state, whose fresh
    /// derivatives are written over junk.
    #[test]
    fn derivatives_refilled_over_another_knots_are_the_fresh_ones() {
        let reference: Vec<Exogenous> = (0..4)
            .map(|k| Exogenous {
                q_d: [0.1 * k as f64, -0.3],
                qd_d: [0.2, 0.05 * k as f64],
                tau_ext: [0.0; 2],
            })
            .collect();
        let c = TrackingCost {
            dof: 2,
            nx: 4,
            control_weights: vec![1.0, 2.0, 1e-4, 3e-4],
            w_p: 1e6,
            w_v: 1e5,
            dt: 0.01,
            reference,
        };
        let (nx, nu) = (12, 4);
        let x = |s: f64| (0..nx).map(|i| s * (i as f64 - 3.5)).collect::<Vec<_>>();
        let u = |s: f64| (0..nu).map(|i| s * (1.0 + i as f64)).collect::<Vec<_>>();
        let bits = |d: &CostDerivatives| {
            let parts = [d.lx.as_slice(), d.lu.as_slice(), d.lxx.as_slice()];
            let parts = [&parts[..], &[d.luu.as_slice(), d.lux.as_slice()]].concat();
            parts
                .concat()
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>()
        };
        let junk = || {
            let mut d = CostDerivatives::new(nx, nu);
            d.lx.fill(f64::NAN);
            d.lu.fill(f64::NAN);
            d.lxx.fill(f64::NAN);
            d.luu.fill(f64::NAN);
            d.lux.fill(f64::NAN);
            d
        };
        let mut fresh = junk();
        c.running_derivatives(2, &x(0.7), &u(-0.4), &mut fresh);
        let mut again = junk();
        c.running_derivatives(0, &x(-1.3), &u(2.0), &mut again);
        c.running_derivatives_again(2, &x(0.7), &u(-0.4), &mut again);
        assert_eq!(bits(&again), bits(&fresh));
        assert!(fresh.lxx.iter().all(|v| v.is_finite()));
        // The Hessian support holds: +0 outside its rows and columns, running and terminal,
        // and the entries on its diagonal are the weights (so it is not wider than it says).
        let r = c
            .hessian_support()
            .expect("the tracking cost knows its support");
        let mut end = junk();
        c.terminal_derivatives(&x(0.3), &mut end);
        for d in [&fresh, &end] {
            for ((i, j), v) in d.lxx.iter().enumerate().map(|(e, v)| ((e % nx, e / nx), v)) {
                if !(r.contains(&i) && r.contains(&j)) {
                    assert_eq!(v.to_bits(), 0, "l_xx ({i}, {j}) outside {r:?}");
                }
            }
            assert!(r.clone().all(|i| d.lxx[(i, i)] > 0.0));
        }
    }
}
