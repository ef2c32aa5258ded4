//! The expansion of every knot for an iteration: the moment step's first derivatives (and,
//! for the Newton model, its second and third) and the cost's derivatives, in parallel.

use super::SoocProblem;
use super::SoocSolver;
use crate::cost::Cost;
use crate::solver::sooc::MomentExpansion;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

impl SoocSolver {
    /// First derivatives of the moment step and the cost derivatives at every knot (in
    /// parallel: the knots are independent); with `third`, the flow's third derivatives for
    /// the Newton model that follows ([`MomentDynamics::expand_with_third`](crate::solver::sooc::MomentDynamics::expand_with_third)).
    pub(super) fn expand(&mut self, problem: &SoocProblem, third: bool) {
        self.expand_by(problem, |k, zk, uk, e| {
            if third {
                problem.dynamics.expand_with_third(k, zk, uk, e);
            } else {
                problem.dynamics.expand(k, zk, uk, e);
            }
        });
    }

    /// [`SoocSolver::expand`] without third derivatives, keeping those of the previous point
    /// ([`MomentDynamics::expand_keeping_third`](crate::solver::sooc::MomentDynamics::expand_keeping_third)).
    pub(super) fn expand_keeping_third(&mut self, problem: &SoocProblem) {
        self.expand_by(problem, |k, zk, uk, e| {
            problem.dynamics.expand_keeping_third(k, zk, uk, e)
        });
    }

    /// [`SoocSolver::expand`] where the expansions may hold the flow's third derivatives of
    /// their points from the previous solve
    /// ([`MomentDynamics::expand_reusing_third`](crate::solver::sooc::MomentDynamics::expand_reusing_third)):
    /// at how many knots they did.
    pub(super) fn expand_reusing_third(&mut self, problem: &SoocProblem, third: bool) -> usize {
        let reused = AtomicUsize::new(0);
        self.expand_by(problem, |k, zk, uk, e| {
            if problem.dynamics.expand_reusing_third(k, zk, uk, third, e) {
                reused.fetch_add(1, Ordering::Relaxed);
            }
        });
        reused.into_inner()
    }

    /// The expansion of every knot by `expand_knot`, and the cost's derivatives.
    fn expand_by(
        &mut self,
        problem: &SoocProblem,
        expand_knot: impl Fn(usize, &[f64], &[f64], &mut MomentExpansion) + Sync,
    ) {
        let h = self.horizon;
        let (z, u) = (&self.z, &self.u);
        self.expansions
            .par_iter_mut()
            .zip(self.derivs[..h].par_iter_mut())
            .enumerate()
            .for_each(|(k, (e, d))| {
                let (zk, uk) = (z[k].as_slice(), u[k].as_slice());
                expand_knot(k, zk, uk, e);
                problem
                    .cost
                    .running_derivatives(k, z[k].as_slice(), u[k].as_slice(), d);
            });
        problem
            .cost
            .terminal_derivatives(self.z[h].as_slice(), &mut self.derivs[h]);
    }
}
