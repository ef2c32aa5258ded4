//! Solvers over a discrete stochastic [`Dynamics`](crate::dynamics::Dynamics) and a
//! [`Cost`](crate::cost::Cost): ILQG (Todorov & Li 2005) with box-constrained controls, and
//! the stagewise Newton solver of the open-loop moment problem (SOOC, [`sooc_newton`]).

pub mod boxqp;
pub mod ilqg;
pub mod moments;
pub mod sooc;
pub mod sooc_fast;
pub mod sooc_newton;
pub mod sparse;

pub use ilqg::{Convergence, Ilqg, IlqgError, IlqgOptions, Solution, StopReason};

use crate::cost::Cost;
use crate::dynamics::Dynamics;

/// Reads a figure that is `+∞` by design in some states (a test not made yet, a model that was
/// not the exact one) from a plan file: JSON has no infinity and `serde_json` writes a non-finite
/// number as `null`, so `null` reads back as `+∞` (a plan stopped early was written but could not
/// be read again).
pub(crate) fn infinite_if_null<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    use serde::Deserialize;
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
}

/// Constant lower and upper limits on every control component (`±∞` for none).
#[derive(Debug, Clone, PartialEq)]
pub struct Bounds {
    pub lower: Vec<f64>,
    pub upper: Vec<f64>,
}

impl Bounds {
    /// No limits on `nu` controls.
    pub fn unbounded(nu: usize) -> Self {
        Bounds {
            lower: vec![f64::NEG_INFINITY; nu],
            upper: vec![f64::INFINITY; nu],
        }
    }

    /// Clamps `u` into the box.
    pub fn clamp(&self, u: &mut [f64]) {
        for ((v, lo), hi) in u.iter_mut().zip(&self.lower).zip(&self.upper) {
            *v = v.clamp(*lo, *hi);
        }
    }

    /// These limits with the `controls` that have a finite lower limit held there (the upper
    /// limit set to it); `None` when none has one (nothing to hold). For the controls that act
    /// only through the deviation from the reference ([`IlqgOptions::held_first`]).
    pub fn holding(&self, controls: &[usize]) -> Option<Bounds> {
        let lower = |i: usize| self.lower.get(i).copied().filter(|l| l.is_finite());
        if !controls
            .iter()
            .any(|&i| lower(i).is_some() && i < self.upper.len())
        {
            return None;
        }
        let mut held = self.clone();
        for &i in controls {
            if let (Some(l), Some(upper)) = (lower(i), held.upper.get_mut(i)) {
                *upper = l;
            }
        }
        Some(held)
    }
}

/// A finite-horizon optimal control problem: dynamics, cost, initial state, horizon, limits.
pub struct Problem<'a> {
    pub dynamics: &'a dyn Dynamics,
    pub cost: &'a dyn Cost,
    pub x0: Vec<f64>,
    /// Number of control steps N (states `x_0 ..= x_N`).
    pub horizon: usize,
    pub bounds: Bounds,
}

impl Problem<'_> {
    /// Deterministic rollout of a control sequence: the states and the total cost.
    pub fn rollout(&self, u: &[nalgebra::DVector<f64>]) -> (Vec<nalgebra::DVector<f64>>, f64) {
        let nx = self.dynamics.nx();
        let mut x = vec![nalgebra::DVector::from_column_slice(&self.x0)];
        let mut cost = 0.0;
        for (k, uk) in u.iter().enumerate().take(self.horizon) {
            let mut next = nalgebra::DVector::zeros(nx);
            self.dynamics
                .step(k, x[k].as_slice(), uk.as_slice(), next.as_mut_slice());
            cost += self.cost.running(k, x[k].as_slice(), uk.as_slice());
            x.push(next);
        }
        cost += self.cost.terminal(x[self.horizon].as_slice());
        (x, cost)
    }
}
