//! Re-solving a SOOC plan one control period later over a horizon of the same length (a receding
//! horizon), tail first.
//!
//! Shifted by `s` knots, the previous plan is a good start everywhere but at its end: its last
//! `s` controls are the last one held, and the horizon now reaches `s` knots past the movement,
//! where the reference holds the target. The gradient of the shifted plan sits in those last
//! knots, and a Newton solve over the whole horizon spends most of its steps moving them, each
//! step an expansion of every knot. Solving the last knots alone first, from the moment state
//! (mean and covariance) the shifted plan reaches where they start, moves them at a fraction of
//! the cost per step; the whole horizon then converges from there in a few steps
//! (`docs/BENCHMARKS.md`, "Criterion cases", times both re-solves on the type-2 arm in the
//! divergent field: `slow/two_link_divergent_sooc_warm_shift2` and `…_tail_first`).

use crate::setup::Setup;
use nalgebra::DVector;
use std::time::{Duration, Instant};
use vic_core::solver::Problem;
use vic_core::solver::sooc::{MomentCost, MomentDynamics};
use vic_core::solver::sooc_newton::{
    SoocError, SoocOptions, SoocProblem, SoocSolution, SoocSolver,
};

/// The share of the horizon solved alone first (chosen on the divergent arm against 20 % and
/// 40 %).
pub const TAIL_SHARE: f64 = 0.3;

/// A tail-first re-solve: the whole horizon's solution (its `solve_time` and `iterations` its
/// own) and what the tail took before it.
#[derive(Debug, Clone)]
pub struct RecedingSolution {
    pub solution: SoocSolution,
    /// Knots solved alone first (0: the tail solve was skipped or failed, see `tail_error`).
    pub tail_knots: usize,
    /// Accepted steps over the tail alone.
    pub tail_iterations: usize,
    /// Everything: the rollout to the tail's start, the tail's solve and the whole one.
    pub total_time: Duration,
    /// Why the tail's solve was abandoned, if it was (the whole horizon then starts from the
    /// shifted plan as it is).
    pub tail_error: Option<SoocError>,
}

/// The workspaces of tail-first re-solves ([`TailFirst::resolve`]), kept from one period to the
/// next as a receding-horizon controller would: one for the whole horizon, one for its tail.
pub struct TailFirst {
    share: f64,
    whole: SoocSolver,
    tail: SoocSolver,
}

impl TailFirst {
    /// Workspaces for `model`'s plant (its moment dynamics' sizes) over `horizon` knots, the last
    /// `⌈share · horizon⌉` of them solved alone first ([`TAIL_SHARE`] unless there is a reason;
    /// 0 for the plain warm start).
    pub fn new(model: &Setup, horizon: usize, share: f64, options: SoocOptions) -> Self {
        let moments = MomentDynamics::new(&model.dynamics);
        let share = share.clamp(0.0, 1.0);
        let tail = tail_knots(share, horizon).max(1);
        TailFirst {
            share,
            whole: SoocSolver::new(&moments, horizon, options.clone()),
            tail: SoocSolver::new(&moments, tail, options),
        }
    }

    /// Re-solves `next` (the movement `s` knots later, [`Setup::shifted`]) from `warm` (the
    /// previous plan shifted by `s`, the last control held): the tail alone first, from the
    /// moment state `warm` reaches where it starts, then the whole horizon from the result. The
    /// tail only chooses the start: the result is [`SoocSolver::solve`]'s from that start, with
    /// its stop and optimality. A tail of no knots, or of all of them, is the plain warm start.
    pub fn resolve(
        &mut self,
        next: &Setup,
        warm: &[DVector<f64>],
    ) -> Result<RecedingSolution, SoocError> {
        let start = Instant::now();
        let horizon = warm.len();
        let tail = tail_knots(self.share, horizon);
        let moments = MomentDynamics::new(&next.dynamics);
        let cost = MomentCost::new(&next.cost, horizon);
        let mut u = warm.to_vec();
        let (mut tail_knots, mut tail_iterations, mut tail_error) = (0, 0, None);
        if tail > 0 && tail < horizon {
            let head = horizon - tail;
            // Where the tail starts: the mean and covariance the shifted plan reaches there.
            let rollout = Problem {
                dynamics: &moments,
                cost: &cost,
                x0: moments.initial_state(&next.x0),
                horizon: head,
                bounds: next.bounds.clone(),
            };
            let (z, _) = rollout.rollout(&warm[..head]);
            let z_tail = z[head].as_slice();
            let rest = next.remaining(head, &z_tail[..next.x0.len()]);
            let rest_moments = MomentDynamics::new(&rest.dynamics);
            let rest_cost = MomentCost::new(&rest.cost, tail);
            let problem = SoocProblem {
                dynamics: &rest_moments,
                cost: &rest_cost,
                x0: z_tail,
                bounds: &rest.bounds,
                horizon: tail,
            };
            match self.tail.solve(&problem, &warm[head..]) {
                Ok(sol) => {
                    u[head..].clone_from_slice(&sol.u);
                    (tail_knots, tail_iterations) = (tail, sol.iterations);
                }
                Err(e) => tail_error = Some(e),
            }
        }
        let problem = SoocProblem {
            dynamics: &moments,
            cost: &cost,
            x0: &next.x0,
            bounds: &next.bounds,
            horizon,
        };
        let solution = self.whole.solve(&problem, &u)?;
        Ok(RecedingSolution {
            solution,
            tail_knots,
            tail_iterations,
            total_time: start.elapsed(),
            tail_error,
        })
    }
}

/// `⌈share · horizon⌉`, at most the horizon.
fn tail_knots(share: f64, horizon: usize) -> usize {
    ((share * horizon as f64).ceil() as usize).min(horizon)
}
