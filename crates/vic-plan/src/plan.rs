//! Planning a scenario: from a validated [`Scenario`] to a solved [`PlanFile`] (the `vic plan`
//! command's work). The set-up lives in [`setup`](crate::setup), the file format in
//! [`plan_file`](crate::plan_file); both are re-exported here.

pub use crate::method::Method;
use crate::plan_file::plan_file;
pub use crate::plan_file::{
    OpenLoopPrediction, PLAN_VERSION, PlanFile, PlanSummary, Stop, final_position_covariance,
};
use crate::prediction::predict_closed_loop;
use crate::scenario::Scenario;
pub use crate::setup::{DelayedCost, DelayedPlant, PlanError, Setup, setup};
use nalgebra::{DMatrix, DVector};
use std::sync::Arc;
use vic_core::dynamics::Dynamics;
use vic_core::model::Noise;
use vic_core::policy::Feedback;
use vic_core::solver::ilqg::{OnIteration, Progress};
use vic_core::solver::sooc::{MomentCost, MomentDynamics, unpack};
use vic_core::solver::sooc_fast::{SoocFastOptions, SoocFastSolver};
use vic_core::solver::sooc_newton::{Optimality, SoocProblem, SoocSolver, SoocStop};
use vic_core::solver::{Ilqg, IlqgOptions, Problem, Solution, StopReason};

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

/// A SOOC solve: the plan as a [`Solution`] (open loop: zero gains) and the optimality verdict.
#[derive(Debug, Clone)]
pub struct SoocResult {
    /// Controls, moment means (the plant states), expected cost, iterations and time; `stop` is
    /// [`StopReason::SmallGradient`] when converged and [`StopReason::MaxIterations`] or
    /// [`StopReason::RegularizationLimit`] otherwise (see `stop` below for the precise reason).
    pub solution: Solution,
    /// Why the solver stopped.
    pub stop: SoocStop,
    /// The first-order optimality at the returned controls.
    pub optimality: Optimality,
}

/// SOOC: minimises the open-loop expected cost of the moment dynamics by stagewise Newton
/// ([`SoocSolver`]) from `warm`, by continuation in the noise level: the problem is solved at
/// `noise_continuation` fractions of the noise in turn, each from the previous solution (the
/// default is the full noise at once; see the configuration).
pub fn solve_sooc(
    setup: &Setup,
    solver: &crate::scenario::SolverSection,
    warm: &[DVector<f64>],
    progress: &Option<ProgressFn>,
) -> Result<SoocResult, PlanError> {
    let start = std::time::Instant::now();
    let mut u = warm.to_vec();
    let mut iterations = 0;
    let mut history = Vec::new();
    let horizon = u.len();
    let options = solver.sooc_options();
    let sizing = MomentDynamics::new(&setup.dynamics);
    let mut workspace = SoocSolver::new(&sizing, horizon, options);
    let stage = Arc::new(std::sync::atomic::AtomicU64::new(0));
    if let Some(p) = progress {
        let (p, stage) = (p.clone(), stage.clone());
        workspace.observer = Some(Arc::new(move |it: &Progress| {
            let fraction = f64::from_bits(stage.load(std::sync::atomic::Ordering::Relaxed));
            p(&format!("open-loop moments (noise × {fraction})"), it);
        }));
    }
    let mut last = None;
    for &fraction in &solver.noise_continuation {
        stage.store(fraction.to_bits(), std::sync::atomic::Ordering::Relaxed);
        let mut dynamics = setup.dynamics.clone();
        dynamics.model.noise = dynamics.model.noise.scaled(fraction);
        let moments = MomentDynamics::new(&dynamics);
        let cost = MomentCost::new(&setup.cost, horizon);
        let problem = SoocProblem {
            dynamics: &moments,
            cost: &cost,
            x0: &setup.x0,
            bounds: &setup.bounds,
            horizon,
        };
        let sol = workspace
            .solve(&problem, &u)
            .map_err(|source| PlanError::Sooc { fraction, source })?;
        iterations += sol.iterations;
        history.extend_from_slice(&sol.history);
        if let Some(p) = progress {
            p(
                "open-loop moments",
                &Progress {
                    iteration: iterations,
                    merit: sol.expected_cost,
                    mu: 0.0,
                    alpha: 1.0,
                },
            );
        }
        u = sol.u.clone();
        last = Some(sol);
    }
    let sol = last.ok_or(PlanError::NoContinuationStage)?;
    let n = setup.x0.len();
    let (nx, nu) = (setup.dynamics.nx(), setup.dynamics.nu());
    let solution = Solution {
        x: sol.z.iter().map(|z| z.rows(0, n).into_owned()).collect(),
        u: sol.u.clone(),
        gains: vec![DMatrix::zeros(nu, nx); horizon],
        cost: f64::NAN,
        expected_cost: sol.expected_cost,
        iterations,
        stop: match sol.stop {
            SoocStop::Converged => StopReason::SmallGradient,
            SoocStop::MaxIterations => StopReason::MaxIterations,
            SoocStop::RegularizationLimit => StopReason::RegularizationLimit,
        },
        solve_time: start.elapsed(),
        history,
        convergence: None,
    };
    Ok(SoocResult {
        solution,
        stop: sol.stop,
        optimality: sol.optimality,
    })
}

/// [`solve_sooc`] by the fast solver ([`SoocFastSolver`]): the same noise continuation, the
/// same problem, its limit of Newton–CG steps the larger of the scenario's iteration limit and
/// the solver's own default.
pub fn solve_sooc_fast(
    setup: &Setup,
    solver: &crate::scenario::SolverSection,
    warm: &[DVector<f64>],
    progress: &Option<ProgressFn>,
) -> Result<SoocResult, PlanError> {
    let start = std::time::Instant::now();
    let mut u = warm.to_vec();
    let mut iterations = 0;
    let mut history = Vec::new();
    let horizon = u.len();
    let defaults = SoocFastOptions::default();
    let options = SoocFastOptions {
        max_iterations: solver
            .sooc_options()
            .max_iterations
            .max(defaults.max_iterations),
        ..defaults
    };
    let sizing = MomentDynamics::new(&setup.dynamics);
    let mut workspace = SoocFastSolver::new(&sizing, horizon, options);
    let mut last = None;
    for &fraction in &solver.noise_continuation {
        let mut dynamics = setup.dynamics.clone();
        dynamics.model.noise = dynamics.model.noise.scaled(fraction);
        let moments = MomentDynamics::new(&dynamics);
        let cost = MomentCost::new(&setup.cost, horizon);
        let problem = SoocProblem {
            dynamics: &moments,
            cost: &cost,
            x0: &setup.x0,
            bounds: &setup.bounds,
            horizon,
        };
        let sol = workspace
            .solve(&problem, &u)
            .map_err(|source| PlanError::Sooc { fraction, source })?;
        iterations += sol.iterations;
        history.extend_from_slice(&sol.history);
        if let Some(p) = progress {
            p(
                "open-loop moments (fast)",
                &Progress {
                    iteration: iterations,
                    merit: sol.expected_cost,
                    mu: 0.0,
                    alpha: 1.0,
                },
            );
        }
        u = sol.u.clone();
        last = Some(sol);
    }
    let sol = last.ok_or(PlanError::NoContinuationStage)?;
    let n = setup.x0.len();
    let (nx, nu) = (setup.dynamics.nx(), setup.dynamics.nu());
    let solution = Solution {
        x: sol.z.iter().map(|z| z.rows(0, n).into_owned()).collect(),
        u: sol.u.clone(),
        gains: vec![DMatrix::zeros(nu, nx); horizon],
        cost: f64::NAN,
        expected_cost: sol.expected_cost,
        iterations,
        stop: match sol.stop {
            SoocStop::Converged => StopReason::SmallGradient,
            SoocStop::MaxIterations => StopReason::MaxIterations,
            SoocStop::RegularizationLimit => StopReason::RegularizationLimit,
        },
        solve_time: start.elapsed(),
        history,
        convergence: None,
    };
    Ok(SoocResult {
        solution,
        stop: sol.stop,
        optimality: sol.optimality,
    })
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
    solver.on_iteration = phase_progress(progress, phase);
    solver
}

/// The progress callback of one phase of a solve.
fn phase_progress(progress: &Option<ProgressFn>, phase: &'static str) -> Option<OnIteration> {
    let p = progress.clone()?;
    Some(Box::new(move |it: &Progress| p(phase, it)))
}

/// Plans a scenario with the given method (ILQG uses the scenario's feedback delay), reporting
/// progress to `progress` if given.
pub fn plan(
    s: &Scenario,
    method: Method,
    progress: Option<ProgressFn>,
) -> Result<PlanFile, PlanError> {
    let setup = setup(s)?;
    let nu = setup.dynamics.nu();
    let steps = s.task.steps;
    let plain = setup.problem(steps);
    let mut verdict = None;
    let (solution, d) = match method {
        Method::Sooc => {
            let (sol, stop) = plan_sooc(s, &setup, &plain, &progress)?;
            verdict = Some(stop);
            (sol, 0)
        }
        Method::SoocFast => {
            let (sol, stop) = plan_sooc_fast(s, &setup, &plain, &progress)?;
            verdict = Some(stop);
            (sol, 0)
        }
        Method::Ilqg if s.task.delay_steps() == 0 => (
            solve_in_phases(&plain, &s.solver.options, &setup.u_init, &progress)?,
            0,
        ),
        Method::Ilqg => (
            plan_delayed(s, &setup, &plain, &progress)?,
            s.task.delay_steps(),
        ),
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
    let mut file = plan_file(s, &setup, &solution, d, nu, method, &open_loop);
    // Whether the feedback's predicted spread stays within the controls' bounds, where the
    // prediction `expected_cost` holds (a delayed plan's naive law is not predicted).
    if method == Method::Ilqg && d == 0 && setup.dynamics.nw() > 0 {
        let policy = file.policy(&setup)?;
        file.summary.clamped_feedback_knots =
            predict_closed_loop(&setup, &policy, Feedback::Full).map(|p| p.clamped_knots);
    }
    if let Some((stop, optimality)) = verdict {
        file.summary.converged = stop == SoocStop::Converged;
        file.summary.stop = stop.into();
        file.summary.optimality = Some(optimality);
    }
    Ok(file)
}

/// The scenario's SOOC plan (`Method::Sooc`) as `vic plan --method sooc` makes it: the open-loop
/// moments optimised by [`solve_sooc`] from the deterministic ILQG optimum (stiffness reset to
/// the configured start when there is noise). Returns the solution (its `cost` the noise-free
/// cost of the plan, `expected_cost` the moment problem's) and the solver's verdict; iterations
/// and time count both solves.
pub fn plan_sooc(
    s: &Scenario,
    setup: &Setup,
    plain: &Problem,
    progress: &Option<ProgressFn>,
) -> Result<(Solution, (SoocStop, Optimality)), PlanError> {
    let (warm, first) = sooc_warm_start(s, setup, plain, progress)?;
    let result = solve_sooc(setup, &s.solver, &warm, progress)?;
    let mut sol = result.solution;
    sol.iterations += first.iterations;
    sol.solve_time += first.solve_time;
    // `cost` is the noise-free cost of the plan; `expected_cost` the moment problem's.
    sol.cost = plain.rollout(&sol.u).1;
    Ok((sol, (result.stop, result.optimality)))
}

/// The scenario's SOOC plan by the fast solver (`Method::SoocFast`, [`solve_sooc_fast`]) from
/// the same start as [`plan_sooc`]'s.
pub fn plan_sooc_fast(
    s: &Scenario,
    setup: &Setup,
    plain: &Problem,
    progress: &Option<ProgressFn>,
) -> Result<(Solution, (SoocStop, Optimality)), PlanError> {
    let (warm, first) = sooc_warm_start(s, setup, plain, progress)?;
    let result = solve_sooc_fast(setup, &s.solver, &warm, progress)?;
    let mut sol = result.solution;
    sol.iterations += first.iterations;
    sol.solve_time += first.solve_time;
    sol.cost = plain.rollout(&sol.u).1;
    Ok((sol, (result.stop, result.optimality)))
}

/// Where a SOOC solve starts: the deterministic ILQG optimum (returned too), its stiffness reset
/// to the configured start when there is noise.
fn sooc_warm_start(
    s: &Scenario,
    setup: &Setup,
    plain: &Problem,
    progress: &Option<ProgressFn>,
) -> Result<(Vec<DVector<f64>>, Solution), PlanError> {
    // Warm start from the deterministic optimum, then optimise the open-loop moments.
    let mut det = solver_for(plain, &s.solver.options, "deterministic", progress);
    det.options.stochastic = false;
    let first = det
        .try_solve_held_first(plain, &setup.u_init)
        .map_err(|source| PlanError::Ilqg {
            phase: "deterministic",
            source,
        })?;
    // The deterministic optimum has almost no stiffness (it buys nothing without noise),
    // and from there the open-loop problem starts in an unstable field with a huge
    // variance. Start the stiffness from the configured initial value instead. Without noise
    // the deterministic optimum *is* the open-loop problem's (the covariance stays 0), and
    // stiffness there would only move the mean through its damping: start from it as it is
    // (on two_link_deterministic, from the configured stiffness the solve crawls for hundreds
    // of iterations to a higher cost; from the deterministic optimum one Newton step confirms
    // it).
    let mut warm = first.u.clone();
    if let Some(off) = s.model.actuator.stiffness_offset(s.model.dof())
        && s.initial_stiffness > 0.0
        && s.model.noise != Noise::None
    {
        for u in &mut warm {
            for i in 0..s.model.dof() {
                u[off + i] = s.initial_stiffness;
            }
            setup.bounds.clamp(u.as_mut_slice());
        }
    }
    Ok((warm, first))
}

/// ILQG on the delay-augmented plant (paper Eq. 13): a command issued at k acts at k + d. The
/// returned states and gains are cut back to the plant's block.
fn plan_delayed(
    s: &Scenario,
    setup: &Setup,
    plain: &Problem,
    progress: &Option<ProgressFn>,
) -> Result<Solution, PlanError> {
    let nx = setup.dynamics.nx();
    let steps = s.task.steps;
    let d = s.task.delay_steps();
    let delayed = setup.delayed(d);
    let problem = delayed.problem(steps);
    // A command issued at k acts at k + d: start from the undelayed plant's plan from
    // the state the commands in flight lead to (the deterministic optimum, exactly).
    let guess_time = std::time::Instant::now();
    let u_init = vic_core::delay::undelayed_guess(
        plain,
        setup.u_init[0].as_slice(),
        d,
        &s.solver.options,
        &setup.u_init,
    )
    .map_err(|source| PlanError::Ilqg {
        phase: "undelayed first guess",
        source,
    })?;
    let guess_time = guess_time.elapsed();
    // Without noise the guess is the deterministic problem's optimum already (see
    // `undelayed_guess`), the first phase of `solve_in_phases`: a deterministic solve from it
    // stops at once, after a linearisation and a backward pass of the augmented plant (a small
    // part of a plan of the single joint with 200 ms of delay). With noise it is the optimum
    // of the tail with the stiffness held, which the stochastic solve re-plans under the
    // noise: it starts from the guess directly either way.
    let stochastic = s.solver.options.stochastic && problem.dynamics.nw() > 0;
    let phase = if stochastic { "stochastic" } else { "ilqg" };
    let mut sol = solver_for(&problem, &s.solver.options, phase, progress)
        .try_solve(&problem, &u_init)
        .map_err(|source| PlanError::Ilqg { phase, source })?;
    sol.solve_time += guess_time;
    for x in &mut sol.x {
        *x = x.rows(0, nx).into_owned();
    }
    for g in &mut sol.gains {
        *g = g.columns(0, nx).into_owned();
    }
    Ok(sol)
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
) -> Result<Solution, PlanError> {
    let failed = |phase| move |source| PlanError::Ilqg { phase, source };
    if !options.stochastic || problem.dynamics.nw() == 0 {
        return solver_for(problem, options, "ilqg", progress)
            .try_solve_held_first(problem, u_init)
            .map_err(failed("ilqg"));
    }
    // One workspace for both phases (a solve starts from nothing but its initial controls):
    // for the 42-state delayed plant a workspace is tens of megabytes.
    let mut solver = solver_for(problem, options, "deterministic", progress);
    solver.options.stochastic = false;
    let first = solver
        .try_solve_held_first(problem, u_init)
        .map_err(failed("deterministic"))?;
    let stochastic = phase_progress(progress, "stochastic");
    solver.options.stochastic = options.stochastic;
    solver.on_iteration = stochastic;
    let mut second = solver
        .try_solve(problem, &first.u)
        .map_err(failed("stochastic"))?;
    second.iterations += first.iterations;
    second.solve_time += first.solve_time;
    Ok(second)
}
