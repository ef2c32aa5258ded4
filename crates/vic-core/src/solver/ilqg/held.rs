//! Deterministic solves that hold some controls at their lower limits first.
//!
//! An impedance's stiffness (paper Eq. 4, `τ = τ_ff − K (q − q_d) − α K q'`) acts only through
//! the deviation from the reference. Without noise its Gauss–Newton curvature in `Q_uu` is its
//! control weight (w_st = 10⁻⁴) plus a term in that deviation squared, so the feedback gains on
//! it, `−Q_uu⁻¹ Q_ux`, are huge wherever the torques do not yet track. From the scenarios' first
//! guess (inverse-dynamics torques along the reference, stiffness at its configured value) the
//! first steps of such a solve are accepted only at short step lengths while μ climbs by orders
//! of magnitude, and a long crawl at α = ½ follows. Their deterministic optimum keeps the
//! stiffness at its lower limit almost everywhere (without noise it buys only the damping of
//! what the torques leave). So the solve first holds it there, a torque-only problem that
//! converges in a few iterations, then frees it from that optimum: far fewer iterations in all,
//! to the free solve's cost within the solver's tolerance (`tests/held_first.rs` checks both;
//! `docs/BENCHMARKS.md`, "Criterion cases", times the `…_free_stiffness` variants against the
//! held ones).
//!
//! Only for first guesses on the reference: the delayed plant's undelayed tail problem starts
//! where the commands in flight left the joint, off the reference, where stiffness buys much
//! (the held optimum costs markedly more) and the free solve from it crawls again (no fewer
//! iterations than a free solve, and a slightly higher stop), so the `delay` module does not hold
//! first when the tail's optimum is the plan (without noise). With noise it holds the stiffness
//! throughout the tail, whose solution is then only the augmented solve's first guess (the
//! delay planner's `tail_bounds`).

use super::{Ilqg, IlqgError, Solution};
use crate::solver::Problem;
use nalgebra::DVector;
use std::time::Instant;

impl Ilqg {
    /// A solve from a first guess (not from a plan: a warm start keeps what it has with
    /// [`Ilqg::try_solve`]): when it is deterministic (no noise in the backward pass, where a
    /// stiffness also buys robustness) and [`IlqgOptions::held_first`](super::IlqgOptions) names
    /// controls with finite lower limits, first with those held there, then all free from that
    /// optimum, within one iteration limit. The free solve's plan and stop; both solves'
    /// iterations, merit history and time.
    /// If the held start cannot be rolled out (a plant that the held controls do not keep
    /// finite), the free solve starts from `u_init` as without holding. Otherwise
    /// [`Ilqg::try_solve`].
    pub fn try_solve_held_first(
        &mut self,
        problem: &Problem,
        u_init: &[DVector<f64>],
    ) -> Result<Solution, IlqgError> {
        let mut out = Solution::empty();
        self.try_solve_held_first_into(problem, u_init, &mut out)?;
        Ok(out)
    }

    /// [`Ilqg::try_solve_held_first`] into `out` (as [`Ilqg::try_solve_into`]; a held first solve
    /// allocates its problem's limits and start state).
    pub fn try_solve_held_first_into(
        &mut self,
        problem: &Problem,
        u_init: &[DVector<f64>],
        out: &mut Solution,
    ) -> Result<(), IlqgError> {
        let deterministic = !self.options.stochastic || self.dims.2 == 0;
        let held_bounds = deterministic.then(|| problem.bounds.holding(&self.options.held_first));
        let Some(bounds) = held_bounds.flatten() else {
            return self.try_solve_into(problem, u_init, out);
        };
        let start = Instant::now();
        // The solve clamps its start into the limits: the held controls start there.
        let held = Problem {
            dynamics: problem.dynamics,
            cost: problem.cost,
            x0: problem.x0.clone(),
            horizon: problem.horizon,
            bounds,
        };
        if self.try_solve_into(&held, u_init, out).is_err() {
            return self.try_solve_into(problem, u_init, out);
        }
        let iterations = out.iterations;
        let mut history = std::mem::take(&mut out.history);
        let first = std::mem::take(&mut out.u);
        // The iteration limit is the whole solve's: the free solve gets what the held one left.
        let limit = self.options.max_iterations;
        self.options.max_iterations = limit - iterations;
        self.iterations_before = iterations;
        let free = self.try_solve_into(problem, &first, out);
        self.iterations_before = 0;
        self.options.max_iterations = limit;
        free?;
        out.iterations += iterations;
        history.extend_from_slice(&out.history);
        out.history = history;
        out.solve_time = start.elapsed();
        Ok(())
    }
}
