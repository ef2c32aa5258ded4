//! Planning a scenario: from a validated [`Scenario`] to a solved [`PlanFile`] (the `vic plan`
//! command's work), and the plan file format other commands read back.

use crate::core::cost::TrackingCost;
use crate::core::delay::Delayed;
use crate::core::dynamics::{Dynamics, EulerModel};
use crate::core::model::{Actuator, Exogenous};
use crate::core::policy::Policy;
use crate::core::solver::ilqg::Progress;
use crate::core::solver::sooc::{MomentCost, MomentDynamics, unpack};
use crate::core::solver::{Bounds, Ilqg, IlqgOptions, Problem, Solution};
use crate::planning::reference;
pub use crate::planning::scenario::Method;
use crate::planning::scenario::{Scenario, TaskPath};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

impl PlanFile {
    /// The policy that executes this plan on the scenario it was made from.
    pub fn policy(&self, setup: &Setup) -> Result<Policy, String> {
        let steps = setup.u_init.len();
        let (nx, nu) = (setup.dynamics.nx(), setup.dynamics.nu());
        if self.u.len() != steps || self.x.len() != steps + 1 {
            return Err(format!(
                "the plan has {} steps, the scenario {steps}: plan and scenario do not match",
                self.u.len()
            ));
        }
        if self.u.iter().any(|u| u.len() != nu) || self.x.iter().any(|x| x.len() != nx) {
            return Err(format!(
                "the plan's controls/states are not {nu}/{nx}-dimensional like the scenario's"
            ));
        }
        let d = self.summary.delay_steps;
        let hold = setup.u_init[0].clone();
        let acting = (0..steps)
            .map(|k| {
                if k < d {
                    hold.clone()
                } else {
                    DVector::from_column_slice(&self.u[k - d])
                }
            })
            .collect();
        let gains = self
            .gains
            .iter()
            .map(|g| {
                let rows = g.len();
                let cols = g.first().map_or(0, |r| r.len());
                DMatrix::from_fn(rows, cols, |r, c| g[r][c])
            })
            .collect::<Vec<_>>();
        let gains = if gains.len() == steps && gains.iter().all(|g| g.shape() == (nu, nx)) {
            gains
        } else {
            vec![DMatrix::zeros(nu, nx); steps]
        };
        Ok(Policy {
            acting,
            nominal: self
                .x
                .iter()
                .map(|x| DVector::from_column_slice(x))
                .collect(),
            gains,
            plan_delay: d,
            bounds: setup.bounds.clone(),
        })
    }
}

/// Plan-file format version; bumped on incompatible changes.
pub const PLAN_VERSION: u32 = 1;

/// Everything needed to solve a scenario with any method.
#[derive(Debug, Clone)]
pub struct Setup {
    pub dynamics: EulerModel,
    pub cost: TrackingCost,
    /// Initial state x₀ (start posture at rest).
    pub x0: Vec<f64>,
    /// Initial guess: inverse dynamics along the reference with the configured initial stiffness.
    pub u_init: Vec<DVector<f64>>,
    pub bounds: Bounds,
    pub reference: Vec<Exogenous>,
}

/// Builds the discrete model, the cost, the start state and the warm start of a scenario.
pub fn setup(s: &Scenario) -> Result<Setup, String> {
    let model = &s.model;
    let (dof, nx, nu) = (model.dof(), model.nx(), model.nu());
    let task = &s.task;
    let steps = task.steps;
    let reference = match &task.path {
        TaskPath::Joint { start, target } => {
            reference::joint_minimum_jerk(start, target, task.duration, task.dt, steps)
        }
        TaskPath::Hand { start, target } => reference::hand_straight_line(
            &model.plant,
            *start,
            *target,
            task.duration,
            task.dt,
            steps,
        )?,
    };

    // Inverse dynamics along the reference (q'' by central differences of q_d').
    let qdd = |k: usize, i: usize| {
        let (a, b) = (k.saturating_sub(1), (k + 1).min(steps));
        (reference[b].qd_d[i] - reference[a].qd_d[i]) / ((b - a) as f64 * task.dt)
    };
    let tau: Vec<[f64; 2]> = (0..=steps)
        .map(|k| {
            let r = &reference[k];
            let acc = [qdd(k, 0), if dof > 1 { qdd(k, 1) } else { 0.0 }];
            model.inverse_dynamics(&r.q_d[..dof], &r.qd_d[..dof], &acc[..dof])
        })
        .collect();
    let k0 = s.initial_stiffness;
    let mut x0 = vec![0.0; nx];
    x0[..dof].copy_from_slice(&reference[0].q_d[..dof]);
    let u_init: Vec<DVector<f64>> = match &model.actuator {
        Actuator::Torque => (0..steps)
            .map(|k| DVector::from_column_slice(&tau[k][..dof]))
            .collect(),
        Actuator::Impedance { .. } => (0..steps)
            .map(|k| {
                let mut u = DVector::from_element(nu, k0);
                u.rows_mut(0, dof).copy_from_slice(&tau[k][..dof]);
                u
            })
            .collect(),
        Actuator::Vsa { motor_inertia } => {
            if k0 <= 0.0 {
                return Err("a VSA plan needs [actuator] initial_stiffness > 0".into());
            }
            // Motor angles that make the spring deliver the torque, and the motor torque that
            // moves the motor along them.
            let theta: Vec<[f64; 2]> = (0..=steps)
                .map(|k| {
                    let mut t = [0.0; 2];
                    for i in 0..dof {
                        t[i] = reference[k].q_d[i] + tau[k][i] / k0;
                    }
                    t
                })
                .collect();
            for i in 0..dof {
                x0[2 * dof + i] = theta[0][i];
            }
            (0..steps)
                .map(|k| {
                    let mut u = DVector::from_element(nu, k0);
                    for i in 0..dof {
                        let (a, b) = (k.saturating_sub(1), (k + 1).min(steps));
                        let acc = if b - a == 2 {
                            (theta[b][i] - 2.0 * theta[k][i] + theta[a][i]) / (task.dt * task.dt)
                        } else {
                            0.0
                        };
                        u[i] = motor_inertia[i] * acc + tau[k][i];
                    }
                    u
                })
                .collect()
        }
    };
    let mut control_weights = vec![s.weights.w_torque; dof];
    control_weights.extend(std::iter::repeat_n(s.weights.w_stiffness, nu - dof));
    let cost = TrackingCost {
        dof,
        nx,
        control_weights,
        w_p: s.weights.w_p,
        w_v: s.weights.w_v,
        dt: task.dt,
        reference: reference.clone(),
    };
    let dynamics = EulerModel {
        model: model.clone(),
        dt: task.dt,
        substeps: task.substeps,
        integrator: task.integrator,
        exogenous: reference.clone(),
    };
    Ok(Setup {
        dynamics,
        cost,
        x0,
        u_init,
        bounds: s.bounds.clone(),
        reference,
    })
}

/// Headline figures of a plan.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct PlanSummary {
    pub method: String,
    pub converged: bool,
    pub stop: String,
    pub iterations: usize,
    /// Cost of the noise-free nominal trajectory.
    pub cost: f64,
    /// Predicted expected cost of the plan's policy.
    pub expected_cost: f64,
    pub solve_ms: f64,
    /// Largest planned stiffness [N m/rad] (0 without a stiffness control).
    pub max_stiffness: f64,
    /// Time-averaged planned stiffness over all joints [N m/rad].
    pub mean_stiffness: f64,
    /// Feedback delay the plan was made for, in steps and ms.
    pub delay_steps: usize,
    pub delay_ms: f64,
    /// Final position error of the nominal trajectory: joint angle [deg] for a single joint, hand
    /// [mm] for the arm.
    pub final_error: f64,
    pub final_error_unit: String,
    /// Expected cost of executing the plan's commands open loop (gains ignored), by covariance
    /// propagation: the common footing of every method.
    pub open_loop_expected_cost: f64,
    /// Predicted standard deviation of the final position executed open loop, in the unit of
    /// `final_error` (for the arm, the square root of the largest eigenvalue of the hand
    /// covariance).
    pub open_loop_final_std: f64,
}

/// A plan as written by `vic plan`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PlanFile {
    pub version: u32,
    /// The scenario file the plan was made from.
    pub scenario: String,
    /// The configuration as resolved (after `--set` overrides).
    pub config: serde_json::Value,
    pub dt: f64,
    /// Knot times `0, Δ, …, N Δ` [s].
    pub time: Vec<f64>,
    pub state_names: Vec<String>,
    pub control_names: Vec<String>,
    /// Nominal states at the knots (the plant's state, without the commands in flight).
    pub x: Vec<Vec<f64>>,
    /// Commands issued at each step (with a delay of d steps, command k acts at step k + d).
    pub u: Vec<Vec<f64>>,
    /// Feedback gains per step, m×n row-major, on the plant state (Eq. 13's block when delayed).
    pub gains: Vec<Vec<Vec<f64>>>,
    /// Reference `q_d`, `q_d'` at the knots [rad, rad/s].
    pub reference: Vec<Exogenous>,
    /// Predicted covariance of the final state executed open loop (n×n, row-major).
    pub open_loop_final_covariance: Vec<Vec<f64>>,
    /// Predicted covariance of the final hand position [m²] (two-link) or of the final joint
    /// angle [rad²] (single joint, 1×1), executed open loop.
    pub open_loop_final_position_covariance: Vec<Vec<f64>>,
    pub summary: PlanSummary,
}

/// What executing a command sequence open loop is predicted to give (covariance propagation).
#[derive(Debug, Clone)]
pub struct OpenLoopPrediction {
    /// Expected cost `E[C]` of the open-loop plant.
    pub expected_cost: f64,
    /// Mean states `m_0 ..= m_N`.
    pub mean: Vec<DVector<f64>>,
    /// Final state covariance `P_N`.
    pub final_covariance: DMatrix<f64>,
}

/// Predicts the open-loop execution of the controls `acting` (those that act at each step) by
/// mean and covariance propagation: feedback gains ignored, so that plans from any method compare
/// on the same footing.
pub fn predict_open_loop(setup: &Setup, acting: &[DVector<f64>]) -> OpenLoopPrediction {
    let moments = MomentDynamics::new(&setup.dynamics);
    let cost = MomentCost::new(&setup.cost, acting.len());
    let problem = Problem {
        dynamics: &moments,
        cost: &cost,
        x0: moments.initial_state(&setup.x0),
        horizon: acting.len(),
        bounds: setup.bounds.clone(),
    };
    let (z, expected_cost) = problem.rollout(acting);
    let n = setup.x0.len();
    let mut final_covariance = DMatrix::zeros(n, n);
    unpack(n, &z[acting.len()].as_slice()[n..], &mut final_covariance);
    OpenLoopPrediction {
        expected_cost,
        mean: z.iter().map(|v| v.rows(0, n).into_owned()).collect(),
        final_covariance,
    }
}

/// Iteration limit of the intermediate stages of the noise continuation.
const INTERMEDIATE_ITERATIONS: usize = 60;

/// SOOC from a warm start, by continuation in the noise level: the open-loop moment problem is
/// solved at `noise_continuation` fractions of the noise in turn, each from the previous
/// solution. Started at full noise from the deterministic plan, the solver can settle in poor local
/// optima (the VSA, whose motor states are noise integrators); the path from small noise follows
/// the deterministic optimum as it deforms.
pub fn solve_sooc(
    setup: &Setup,
    solver: &crate::planning::scenario::IlqgSection,
    warm: &[DVector<f64>],
    progress: &Option<ProgressFn>,
) -> Solution {
    let mut u = warm.to_vec();
    let mut total: Option<Solution> = None;
    let stages = solver.noise_continuation.len();
    for (stage, &fraction) in solver.noise_continuation.iter().enumerate() {
        let mut dynamics = setup.dynamics.clone();
        dynamics.model.noise = dynamics.model.noise.scaled(fraction);
        let moments = MomentDynamics::new(&dynamics);
        let cost = MomentCost::new(&setup.cost, u.len());
        let problem = Problem {
            dynamics: &moments,
            cost: &cost,
            x0: moments.initial_state(&setup.x0),
            horizon: u.len(),
            bounds: setup.bounds.clone(),
        };
        let mut options = solver.options.clone();
        if stage + 1 < stages {
            // Intermediate noise levels only need to bring the plan near the next one's basin.
            options.max_iterations = options.max_iterations.min(INTERMEDIATE_ITERATIONS);
        }
        let mut ilqg = solver_for(&problem, &options, "open-loop moments", progress);
        let mut sol = ilqg.solve(&problem, &u);
        u = sol.u.clone();
        if let Some(prev) = total {
            sol.iterations += prev.iterations;
            sol.solve_time += prev.solve_time;
        }
        total = Some(sol);
    }
    total.expect("at least one continuation stage")
}

/// A progress report: the phase of the solve and the solver's state after an iteration.
pub type ProgressFn = Arc<dyn Fn(&str, &Progress) + Send + Sync>;

fn solver_for(
    problem: &Problem,
    options: &IlqgOptions,
    phase: &'static str,
    progress: &Option<ProgressFn>,
) -> Ilqg {
    let mut solver = Ilqg::new(problem, options.clone());
    if let Some(p) = progress.clone() {
        solver.on_iteration = Some(Box::new(move |it: &Progress| p(phase, it)));
    }
    solver
}

/// Plans a scenario with the given method (ILQG uses the scenario's feedback delay), reporting
/// progress to `progress` if given.
pub fn plan(
    s: &Scenario,
    method: Method,
    progress: Option<ProgressFn>,
) -> Result<PlanFile, String> {
    let setup = setup(s)?;
    let (nx, nu) = (setup.dynamics.nx(), setup.dynamics.nu());
    let steps = s.task.steps;
    let plain = Problem {
        dynamics: &setup.dynamics,
        cost: &setup.cost,
        x0: setup.x0.clone(),
        horizon: steps,
        bounds: setup.bounds.clone(),
    };
    let (solution, d) = match method {
        Method::Sooc => {
            // Warm start from the deterministic optimum, then optimise the open-loop moments.
            let mut det = solver_for(&plain, &s.solver.options, "deterministic", &progress);
            det.options.stochastic = false;
            let first = det.solve(&plain, &setup.u_init);
            // The deterministic optimum has almost no stiffness (it buys nothing without noise),
            // and from there the open-loop problem starts in an unstable field with a huge
            // variance. Start the stiffness from the configured initial value instead.
            let mut warm = first.u.clone();
            if let Some(off) = s.model.actuator.stiffness_offset(s.model.dof())
                && s.initial_stiffness > 0.0
            {
                for u in &mut warm {
                    for i in 0..s.model.dof() {
                        u[off + i] = s.initial_stiffness;
                    }
                    setup.bounds.clamp(u.as_mut_slice());
                }
            }
            let mut sol = solve_sooc(&setup, &s.solver, &warm, &progress);
            sol.iterations += first.iterations;
            sol.solve_time += first.solve_time;
            // `cost` is the noise-free cost of the plan; `expected_cost` the moment problem's.
            sol.cost = plain.rollout(&sol.u).1;
            for x in &mut sol.x {
                *x = x.rows(0, nx).into_owned();
            }
            // Executed open loop: no feedback gains.
            for g in &mut sol.gains {
                *g = DMatrix::zeros(nu, nx);
            }
            (sol, 0)
        }
        Method::Ilqg if s.task.delay_steps() == 0 => (
            solve_in_phases(&plain, &s.solver.options, &setup.u_init, &progress)?,
            0,
        ),
        Method::Ilqg => {
            let d = s.task.delay_steps();
            let delayed = Delayed::new(setup.dynamics.clone(), d);
            let x0 = delayed.initial_state(&setup.x0, setup.u_init[0].as_slice());
            let cost = DelayedCost {
                inner: &setup.cost,
                nx,
            };
            let problem = Problem {
                dynamics: &delayed,
                cost: &cost,
                x0,
                horizon: steps,
                bounds: setup.bounds.clone(),
            };
            // A command issued at k acts at k + d: start from the undelayed plant's plan from
            // the state the commands in flight lead to (the deterministic optimum, exactly).
            let guess_time = std::time::Instant::now();
            let u_init = crate::core::delay::undelayed_guess(
                &plain,
                setup.u_init[0].as_slice(),
                d,
                &s.solver.options,
                &setup.u_init,
            )
            .map_err(|e| format!("planning the undelayed first guess: {e}"))?;
            let guess_time = guess_time.elapsed();
            let mut sol = solve_in_phases(&problem, &s.solver.options, &u_init, &progress)?;
            sol.solve_time += guess_time;
            for x in &mut sol.x {
                *x = x.rows(0, nx).into_owned();
            }
            for g in &mut sol.gains {
                *g = g.columns(0, nx).into_owned();
            }
            (sol, d)
        }
    };
    // The commands that act at each step: with a delay, the hold command first.
    let acting: Vec<DVector<f64>> = (0..steps)
        .map(|k| {
            if k < d {
                setup.u_init[0].clone()
            } else {
                solution.u[k - d].clone()
            }
        })
        .collect();
    let open_loop = predict_open_loop(&setup, &acting);
    Ok(plan_file(s, &setup, &solution, d, nu, method, &open_loop))
}

/// Solves a stochastic problem by continuation: first the deterministic problem (whose landscape
/// is benign), then the stochastic one from its solution. Started far from the optimum, the noise
/// terms can lead ILQG to poor local solutions in an unstable field. Iterations and solve time
/// add up over the phases.
pub fn solve_in_phases(
    problem: &Problem,
    options: &IlqgOptions,
    u_init: &[DVector<f64>],
    progress: &Option<ProgressFn>,
) -> Result<Solution, String> {
    let start = |e: crate::core::solver::IlqgError| format!("ILQG: {e}");
    if !options.stochastic || problem.dynamics.nw() == 0 {
        return solver_for(problem, options, "ilqg", progress)
            .try_solve(problem, u_init)
            .map_err(start);
    }
    let mut solver = solver_for(problem, options, "deterministic", progress);
    solver.options.stochastic = false;
    let first = solver.try_solve(problem, u_init).map_err(start)?;
    let mut solver = solver_for(problem, options, "stochastic", progress);
    let mut second = solver.try_solve(problem, &first.u).map_err(start)?;
    second.iterations += first.iterations;
    second.solve_time += first.solve_time;
    Ok(second)
}

/// The cost of the plain plant applied to the plant block of a delay-augmented state.
pub struct DelayedCost<'a> {
    inner: &'a TrackingCost,
    nx: usize,
}

impl<'a> DelayedCost<'a> {
    /// Wraps `inner`, a cost on the first `nx` components of the state.
    pub fn new(inner: &'a TrackingCost, nx: usize) -> Self {
        DelayedCost { inner, nx }
    }
}

impl crate::core::cost::Cost for DelayedCost<'_> {
    fn running(&self, k: usize, x: &[f64], u: &[f64]) -> f64 {
        self.inner.running(k, &x[..self.nx], u)
    }
    fn terminal(&self, x: &[f64]) -> f64 {
        self.inner.terminal(&x[..self.nx])
    }
    fn running_derivatives(
        &self,
        k: usize,
        x: &[f64],
        u: &[f64],
        d: &mut crate::core::cost::CostDerivatives,
    ) {
        // The augmented derivatives are zero outside the plant block. The tracking cost clears
        // every entry it is given and writes only the joint angles and velocities (the first
        // 2·dof components), so it fills the augmented derivatives in place, without a copy
        // (and without allocating in the solver's iterations).
        debug_assert!(self.inner.nx <= x.len());
        self.inner.running_derivatives(k, x, u, d);
    }
    fn terminal_derivatives(&self, x: &[f64], d: &mut crate::core::cost::CostDerivatives) {
        self.inner.terminal_derivatives(x, d);
    }
}

fn plan_file(
    s: &Scenario,
    setup: &Setup,
    sol: &Solution,
    d: usize,
    nu: usize,
    method: Method,
    open_loop: &OpenLoopPrediction,
) -> PlanFile {
    let model = &s.model;
    let dof = model.dof();
    let dt = s.task.dt;
    let steps = s.task.steps;
    let stiffness: Vec<f64> = match model.actuator.stiffness_offset(dof) {
        Some(off) => sol
            .u
            .iter()
            .flat_map(|u| u.rows(off, dof).iter().copied().collect::<Vec<_>>())
            .collect(),
        None => vec![],
    };
    let max_stiffness = stiffness.iter().copied().fold(0.0, f64::max);
    let mean_stiffness = if stiffness.is_empty() {
        0.0
    } else {
        stiffness.iter().sum::<f64>() / stiffness.len() as f64
    };
    let last = &sol.x[steps];
    let target = &setup.reference[steps];
    let (final_error, unit) = if dof == 1 {
        ((last[0] - target.q_d[0]).abs().to_degrees(), "deg")
    } else {
        let p = model.plant.hand_position(&last.as_slice()[..2]);
        let t = model.plant.hand_position(&target.q_d);
        (
            ((p[0] - t[0]).powi(2) + (p[1] - t[1]).powi(2)).sqrt() * 1000.0,
            "mm",
        )
    };
    let (position_cov, open_loop_final_std) =
        final_position_covariance(model, &open_loop.mean[steps], &open_loop.final_covariance);
    let joints: Vec<String> = (1..=dof)
        .map(|i| {
            if dof == 1 {
                "q".to_string()
            } else {
                format!("q{i}")
            }
        })
        .collect();
    let mut state_names: Vec<String> = joints.clone();
    state_names.extend(joints.iter().map(|j| format!("{j}_dot")));
    if matches!(model.actuator, Actuator::Vsa { .. }) {
        let motors: Vec<String> = (1..=dof).map(|i| format!("theta{i}")).collect();
        state_names.extend(motors.clone());
        state_names.extend(motors.iter().map(|m| format!("{m}_dot")));
    }
    let mut control_names: Vec<String> = (1..=dof).map(|i| format!("tau{i}")).collect();
    if nu > dof {
        control_names.extend((1..=dof).map(|i| format!("k{i}")));
    }
    PlanFile {
        version: PLAN_VERSION,
        scenario: s.source.display().to_string(),
        config: serde_json::to_value(&s.resolved).unwrap_or(serde_json::Value::Null),
        dt,
        time: (0..=steps).map(|k| k as f64 * dt).collect(),
        state_names,
        control_names,
        x: sol.x.iter().map(|v| v.iter().copied().collect()).collect(),
        u: sol.u.iter().map(|v| v.iter().copied().collect()).collect(),
        gains: sol
            .gains
            .iter()
            .map(|g| g.row_iter().map(|r| r.iter().copied().collect()).collect())
            .collect(),
        reference: setup.reference.clone(),
        open_loop_final_covariance: rows(&open_loop.final_covariance),
        open_loop_final_position_covariance: rows(&position_cov),
        summary: PlanSummary {
            method: method.name().into(),
            converged: sol.stop.converged(),
            stop: format!("{:?}", sol.stop),
            iterations: sol.iterations,
            cost: sol.cost,
            expected_cost: sol.expected_cost,
            solve_ms: sol.solve_time.as_secs_f64() * 1000.0,
            max_stiffness,
            mean_stiffness,
            delay_steps: d,
            delay_ms: d as f64 * dt * 1000.0,
            final_error,
            final_error_unit: unit.into(),
            open_loop_expected_cost: open_loop.expected_cost,
            open_loop_final_std,
        },
    }
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

/// The covariance of the final position (hand for the arm, `J P_qq Jᵀ`; joint angle for a single
/// joint) and its largest standard deviation in mm (arm) or degrees (joint).
pub fn final_position_covariance(
    model: &crate::core::model::ArmModel,
    mean: &DVector<f64>,
    cov: &DMatrix<f64>,
) -> (DMatrix<f64>, f64) {
    if model.dof() == 1 {
        let c = DMatrix::from_element(1, 1, cov[(0, 0)]);
        (c, cov[(0, 0)].max(0.0).sqrt().to_degrees())
    } else {
        let j = model.plant.jacobian(&mean.as_slice()[..2]);
        let jm = DMatrix::from_row_slice(2, 2, &[j[0][0], j[0][1], j[1][0], j[1][1]]);
        let pq = cov.view((0, 0), (2, 2));
        let c = &jm * pq * jm.transpose();
        let (tr, det) = (
            c[(0, 0)] + c[(1, 1)],
            c[(0, 0)] * c[(1, 1)] - c[(0, 1)] * c[(1, 0)],
        );
        let largest = 0.5 * (tr + (tr * tr - 4.0 * det).max(0.0).sqrt());
        (c, largest.max(0.0).sqrt() * 1000.0)
    }
}
