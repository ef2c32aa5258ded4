//! Receding-horizon stiffness planning: the `replan` strategy of a central controller that sees
//! the state `D` steps late (paper Eq. 11–13, 19; issue 13).
//!
//! Every central period (`period_steps` knots: 2 at Δ = 10 ms and 50 Hz) the controller
//! predicts the present state `x̂_k` from the delayed measurement over the commands in flight
//! (the predictor's own [`predict_present`]), re-solves the open-loop problem of SOOC (Berret &
//! Jean 2020; the moment dynamics and Eq. 14's expected cost) from `x̂_k` to the end of the
//! movement, warm-started from the previous plan's remaining commands (the shifted previous
//! solution), with at most `max_iterations` Newton steps, and plays the result open loop until
//! the next period. Between replans nothing is fed back: what corrects a deviation is the next
//! plan's torque *and* stiffness.
//!
//! The start of each re-solve: mean `x̂_k`, and a covariance. By default **zero**: a state
//! believed exact. What that leaves out is the prediction error, the noise that entered during
//! the latency and that no measurement has shown yet; with `uncertain_steps = D` the re-solve
//! starts with the covariance that `D` (plus the lead) steps of noise add to a state known
//! exactly, propagated by the moment dynamics (Eq. 11) along the plan's commands from `x̂_k` (the
//! exact prediction error runs along the commands applied since the seen state: the same number
//! of steps of the same noise from the same neighbourhood). Not the previous plan's open-loop
//! covariance at knot `k`: that describes a controller that never measured anything since the
//! start. Neither start is right everywhere (`tests/replan.rs` runs the pulses and prints the
//! figures): on the single joint at 200 ms after a pulse, re-solves believing the present exact
//! buy too little stiffness and correct by torque alone, 200 ms late, so the joint swings far
//! more than under the stiffness plan, and the covariance start does not; on the arm in the
//! divergent field after a pulse the covariance start ends farther off than the stiffness plan
//! while the exact start ends nearer, and without a pulse the two starts end alike. The default
//! stays the exact start, which every result in the documents uses.
//!
//! Acceptance: converged or not, the new commands replace the old ones only when they are finite
//! and their open-loop expected cost from `x̂_k` is not worse than the old plan's remaining
//! commands from the same `x̂_k`; otherwise the old plan goes on ("a solve that misses its period
//! sends the previous plan's slice, never nothing").

use crate::cost::TrackingCost;
use crate::dynamics::{DiscreteDynamics, Dynamics};
use crate::policy::{Policy, predict_present};
use crate::scalar::MAX_NX;
use crate::solver::Problem;
use crate::solver::sooc::{MomentCost, MomentDynamics};
use crate::solver::sooc_newton::{SoocOptions, SoocProblem, SoocSolver, SoocStop};
use nalgebra::DVector;
use serde::{Deserialize, Serialize};

/// Newton iterations per re-solve. On the arm three stagewise Newton steps without the third
/// derivatives take a large part of the 20 ms central period (fewer knots as the horizon
/// shrinks, so less), which is why the live controller re-solves in the background with a lead
/// (the solver bench's `slow/two_link_divergent_replan_knot2`: `docs/BENCHMARKS.md`, "Solver
/// targets" and "Live replanner"). From a warm start the first steps take most of the decrease,
/// and three keep a Monte Carlo of the arm affordable.
pub(crate) const REPLAN_MAX_ITERATIONS: usize = 3;

/// The central period of the paper's iCub layer [s] (50 Hz).
pub(crate) const CENTRAL_PERIOD_S: f64 = 0.02;

/// How often and how hard the controller replans.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ReplanOptions {
    /// Knots between re-solves (one central period).
    pub period_steps: usize,
    /// Newton iterations per re-solve.
    pub max_iterations: usize,
    /// Knots between the measurement a re-solve starts from and the knot its commands take over
    /// (0: at once). A controller whose re-solve takes up to a period plans from the state
    /// predicted `lead_steps` ahead over the commands it will send meanwhile (the old plan's),
    /// and adopts the result at that knot: the law a background re-solve executes (the live
    /// central controller, [`Replanner::predict_for`]).
    #[serde(default)]
    pub lead_steps: usize,
    /// Start each re-solve with the covariance of the prediction error, the noise of this many
    /// knots the controller has not seen (the feedback latency `D`; the lead is added), see
    /// [`Replanner::replan_from`]. 0 (the default) starts it from a state believed exact.
    #[serde(default)]
    pub uncertain_steps: usize,
    /// Whether each re-solve's Newton model includes the flow's third derivatives (the exact
    /// Hessian; [`SoocOptions::flow_third_derivatives`]). Off by default: with at most
    /// [`REPLAN_MAX_ITERATIONS`] warm-started steps a re-solve never reaches the tolerances that
    /// need the exact model, and the third derivatives are most of each step's cost. From the
    /// plan's own mean one exact step converges in the time of three Gauss–Newton steps, but a
    /// re-solve starts from a measured state, and from states off the plan the exact steps cost
    /// more and end no lower except after a large deviation (`docs/BENCHMARKS.md`, "Approaches
    /// that did not pay").
    #[serde(default)]
    pub flow_third_derivatives: bool,
}

impl ReplanOptions {
    /// One re-solve per central period of [`CENTRAL_PERIOD_S`] on a grid of `dt` [s], capped at
    /// [`REPLAN_MAX_ITERATIONS`].
    pub fn at_50_hz(dt: f64) -> Self {
        ReplanOptions {
            period_steps: ((CENTRAL_PERIOD_S / dt).round() as usize).max(1),
            max_iterations: REPLAN_MAX_ITERATIONS,
            lead_steps: 0,
            uncertain_steps: 0,
            flow_third_derivatives: false,
        }
    }
}

/// What the re-solves of a trial did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct ReplanStats {
    /// Re-solves started.
    pub solves: usize,
    /// Re-solves whose commands replaced the old plan's.
    pub accepted: usize,
    /// Re-solves that met SOOC's convergence criterion within the cap.
    pub converged: usize,
    /// Re-solves that failed (non-finite start) or came back worse or not finite: the old plan
    /// went on.
    pub(crate) kept_old: usize,
    /// Newton iterations over all re-solves.
    pub iterations: usize,
}

impl ReplanStats {
    /// What happened between `before` and now.
    pub fn since(&self, before: &ReplanStats) -> ReplanStats {
        ReplanStats {
            solves: self.solves - before.solves,
            accepted: self.accepted - before.accepted,
            converged: self.converged - before.converged,
            kept_old: self.kept_old - before.kept_old,
            iterations: self.iterations - before.iterations,
        }
    }

    /// Adds `other`'s counts.
    pub fn add(&mut self, other: &ReplanStats) {
        self.solves += other.solves;
        self.accepted += other.accepted;
        self.converged += other.converged;
        self.kept_old += other.kept_old;
        self.iterations += other.iterations;
    }
}

/// How one re-solve ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ReplanOutcome {
    /// The new commands replaced the old ones: expected cost from `x̂` before and after.
    Accepted { old_cost: f64, new_cost: f64 },
    /// The old plan goes on (the solve failed, or its result was not finite or not better).
    KeptOld,
}

/// A receding-horizon controller for one trial: the plan it is playing and what it needs to
/// re-solve it. [`Replanner::reset`] restores the first plan for the next trial.
#[derive(Debug, Clone)]
pub struct Replanner {
    pub options: ReplanOptions,
    /// The controller's model of the plant (it knows no disturbance).
    dynamics: DiscreteDynamics,
    cost: TrackingCost,
    /// The plan made before the movement (the SOOC plan).
    original: Vec<DVector<f64>>,
    /// The plan being played: the original with every accepted re-solve written over its tail.
    plan: Policy,
    pub stats: ReplanStats,
    workspace: Workspace,
}

/// The re-solves' SOOC workspace, kept from one re-solve to the next. Over a movement the
/// horizon only shrinks, which [`SoocSolver::solve`] does without allocating: a trial allocates
/// it at its first re-solve only. Scratch, not state: a clone (the live controller's worker
/// thread) starts without one, and a re-solve's result does not depend on it (to the bit).
#[derive(Default)]
struct Workspace(Option<SoocSolver>);

impl Clone for Workspace {
    fn clone(&self) -> Self {
        Workspace(None)
    }
}

impl std::fmt::Debug for Workspace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let horizon = self.0.as_ref().map(SoocSolver::horizon);
        f.debug_tuple("Workspace").field(&horizon).finish()
    }
}

impl Replanner {
    /// Replans `policy` (an open-loop plan of torque and stiffness; its gains are ignored) on the
    /// controller's model `dynamics` with the cost `cost`.
    pub fn new(
        policy: &Policy,
        dynamics: &DiscreteDynamics,
        cost: &TrackingCost,
        options: ReplanOptions,
    ) -> Self {
        let mut plan = policy.clone();
        plan.gains.clear();
        Replanner {
            options,
            dynamics: dynamics.clone(),
            cost: cost.clone(),
            original: policy.acting.clone(),
            plan,
            stats: ReplanStats::default(),
            workspace: Workspace::default(),
        }
    }

    /// Back to the plan made before the movement, statistics cleared.
    pub fn reset(&mut self) {
        for (a, o) in self.plan.acting.iter_mut().zip(&self.original) {
            a.copy_from(o);
        }
        self.stats = ReplanStats::default();
    }

    /// The commands being played (knots `0..N`).
    pub fn plan(&self) -> &[DVector<f64>] {
        &self.plan.acting
    }

    /// Whether the controller re-solves at knot `k`: once per period, after the start (knot 0
    /// plays the plan made from the start state) and before the last knot.
    pub(crate) fn replans_at(&self, k: usize) -> bool {
        k > 0 && k + 1 < self.plan.steps() && k.is_multiple_of(self.options.period_steps)
    }

    /// The command of knot `k` for a controller holding the state `x` of knot `seen` (or none
    /// yet), the commands `applied` since (knots `seen..k`): at a replanning knot, predicts the
    /// state of the knot the re-solve takes over at into `scratch` (`≥ nx`, see
    /// [`Replanner::predict_for`]) and re-solves from it; then the plan's command.
    /// Returns the re-solve's outcome, if one ran.
    pub fn command_into<'a>(
        &mut self,
        k: usize,
        seen: Option<(usize, &[f64])>,
        applied: impl IntoIterator<Item = &'a [f64]>,
        scratch: &mut [f64],
        u: &mut [f64],
    ) -> Option<ReplanOutcome> {
        let nx = seen.map_or(0, |(_, x)| x.len());
        let outcome = self
            .predict_for(k, seen, applied, scratch)
            .map(|k0| self.replan_from(k0, &scratch[..nx]));
        self.plan.control_into(k, None, u);
        outcome
    }

    /// At a replanning knot `k` with a state seen: the knot `k0 = k + lead_steps` a re-solve
    /// takes over at, and its predicted state in `scratch` — the present predicted from the state
    /// of knot `seen` over the commands `applied` since (knots `seen..k`), then over the plan's
    /// own commands of knots `k..k0` (what the controller sends while it re-solves). `None`
    /// where no re-solve runs (not a replanning knot, no state yet, or `k0` at the end).
    pub fn predict_for<'a>(
        &self,
        k: usize,
        seen: Option<(usize, &[f64])>,
        applied: impl IntoIterator<Item = &'a [f64]>,
        scratch: &mut [f64],
    ) -> Option<usize> {
        let (l, x) = seen.filter(|_| self.replans_at(k))?;
        let k0 = k + self.options.lead_steps;
        if k0 + 1 >= self.plan.steps() {
            return None;
        }
        predict_present(&self.dynamics, l, x, applied, scratch);
        if k0 > k {
            let n = x.len();
            let mut present = [0.0; MAX_NX];
            present[..n].copy_from_slice(&scratch[..n]);
            let ahead = self.plan.acting[k..k0].iter().map(|u| u.as_slice());
            predict_present(&self.dynamics, k, &present[..n], ahead, scratch);
        }
        Some(k0)
    }

    /// The plan's command of knot `k` (no re-solve).
    pub fn plan_command_into(&self, k: usize, u: &mut [f64]) {
        self.plan.control_into(k, None, u);
    }

    /// The plan's commands from knot `k0` on: the warm start of a re-solve made elsewhere.
    pub fn tail(&self, k0: usize) -> &[DVector<f64>] {
        &self.plan.acting[k0..]
    }

    /// Writes `commands` (a plan from knot `k0`) over the plan's commands of knots `from..`
    /// (`from ≥ k0`: the knots before `from` were already sent).
    pub fn adopt(&mut self, k0: usize, from: usize, commands: &[DVector<f64>]) {
        let skip = from.saturating_sub(k0);
        for (a, u) in self.plan.acting[k0 + skip..]
            .iter_mut()
            .zip(commands.iter().skip(skip))
        {
            a.copy_from(u);
        }
    }

    /// Re-solves the open-loop problem from the state `x` at knot `k0` to the end of the
    /// movement, warm-started from the plan's remaining commands, and keeps the result if it is
    /// finite and not worse than them.
    pub fn replan_from(&mut self, k0: usize, x: &[f64]) -> ReplanOutcome {
        self.stats.solves += 1;
        let horizon = self.plan.steps() - k0;
        // The problem from knot k0 on: the reference (and the cost's targets) shifted by k0.
        let mut dynamics = self.dynamics.clone();
        dynamics
            .exogenous
            .drain(..k0.min(dynamics.exogenous.len() - 1));
        let mut cost = self.cost.clone();
        cost.reference.drain(..k0.min(cost.reference.len() - 1));
        let moments = MomentDynamics::new(&dynamics);
        let moment_cost = MomentCost::new(&cost, horizon);
        let warm = &self.plan.acting[k0..];
        let z0 = self.initial_moments(&MomentDynamics::new(&self.dynamics), k0, x);
        let old_cost = Problem {
            dynamics: &moments,
            cost: &moment_cost,
            x0: z0.clone(),
            horizon,
            bounds: self.plan.bounds.clone(),
        }
        .rollout(warm)
        .1;
        let problem = SoocProblem {
            dynamics: &moments,
            cost: &moment_cost,
            x0: &z0,
            bounds: &self.plan.bounds,
            horizon,
        };
        let options = SoocOptions {
            max_iterations: self.options.max_iterations,
            flow_third_derivatives: self.options.flow_third_derivatives,
            ..SoocOptions::default()
        };
        let solver = self
            .workspace
            .0
            .get_or_insert_with(|| SoocSolver::new(&moments, horizon, options.clone()));
        solver.options = options;
        let Ok(sol) = solver.solve(&problem, warm) else {
            self.stats.kept_old += 1;
            return ReplanOutcome::KeptOld;
        };
        self.stats.iterations += sol.iterations;
        if sol.stop == SoocStop::Converged {
            self.stats.converged += 1;
        }
        let finite =
            sol.expected_cost.is_finite() && sol.u.iter().all(|u| u.iter().all(|v| v.is_finite()));
        // `old_cost` not finite (the old plan blows up from here): any finite plan is better.
        if !finite || sol.expected_cost > old_cost {
            self.stats.kept_old += 1;
            return ReplanOutcome::KeptOld;
        }
        for (a, u) in self.plan.acting[k0..].iter_mut().zip(&sol.u) {
            a.copy_from(u);
        }
        self.stats.accepted += 1;
        ReplanOutcome::Accepted {
            old_cost,
            new_cost: sol.expected_cost,
        }
    }

    /// The moment state a re-solve from the predicted mean `x` at knot `k0` starts from: `x`,
    /// and the covariance that `uncertain_steps + lead_steps` steps of noise add to a state known
    /// exactly, along the plan's commands from `k0` (fewer near the end of the movement); zero
    /// covariance when `uncertain_steps` is 0.
    fn initial_moments(&self, moments: &MomentDynamics, k0: usize, x: &[f64]) -> Vec<f64> {
        let steps = match self.options.uncertain_steps {
            0 => 0,
            d => d + self.options.lead_steps,
        };
        let mut z = moments.initial_state(x);
        let mut next = z.clone();
        for k in k0..(k0 + steps).min(self.plan.steps()) {
            moments.step(k, &z, self.plan.acting[k].as_slice(), &mut next);
            std::mem::swap(&mut z, &mut next);
        }
        // Only the covariance: the mean is the prediction's.
        z[..x.len()].copy_from_slice(x);
        z
    }

    /// The controller's model.
    pub fn dynamics(&self) -> &DiscreteDynamics {
        &self.dynamics
    }
}

/// What a controller executes in a trial: a plan with a feedback law, or a receding-horizon
/// replanner. The Monte Carlo and the central controller both drive this, so that offline,
/// lockstep and live execute one law.
#[derive(Debug, Clone)]
pub enum Executor<'a> {
    Plan {
        policy: &'a Policy,
        feedback: crate::policy::Feedback,
    },
    Replan(Box<Replanner>),
}

impl Executor<'_> {
    /// The command of knot `k` (see [`Policy::command_into`] and [`Replanner::command_into`]).
    /// `dynamics` is the controller's model (the replanner carries its own).
    pub fn command_into<'b>(
        &mut self,
        dynamics: &dyn Dynamics,
        k: usize,
        seen: Option<(usize, &[f64])>,
        applied: impl IntoIterator<Item = &'b [f64]>,
        scratch: &mut [f64],
        u: &mut [f64],
    ) {
        match self {
            Executor::Plan { policy, feedback } => {
                policy.command_into(dynamics, k, *feedback, seen, applied, scratch, u)
            }
            Executor::Replan(r) => {
                r.command_into(k, seen, applied, scratch, u);
            }
        }
    }
}
