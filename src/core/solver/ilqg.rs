//! Iterative LQG for stochastic plants with state- and control-dependent noise (Todorov & Li 2005,
//! DESIGN §4), with box-constrained controls by projected Newton (Tassa, Mansard & Todorov 2014),
//! adaptive Levenberg–Marquardt regularisation and a backtracking line search.
//!
//! The line search compares *expected* costs when the plant is stochastic: the nominal cost plus
//! the second-order noise cost of the candidate under the new feedback gains
//! ([`crate::core::solver::moments::expected_cost`]). The deterministic cost alone would reject the very steps the noise
//! terms of the backward pass ask for.

use super::boxqp::{MAX_QP, QpStatus, SmallCholesky, solve_box_qp};
use super::sparse::SparseLinearization;
use super::{Bounds, Problem};
use crate::core::cost::CostDerivatives;
use crate::core::dynamics::{Linearization, NoiseKind};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use std::time::{Duration, Instant};

/// Regularisation, relative to the mean diagonal of the value Hessian `S_0`, below which the
/// backward pass's model is trusted for a convergence verdict.
const TRUSTED_MU: f64 = 1e-3;

/// Solver settings. Defaults suit the paper's problems.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IlqgOptions {
    /// Iteration limit (default 200).
    pub max_iterations: usize,
    /// Stop when a step improves (or is predicted to improve) the cost by less than this fraction
    /// (default 1e-6).
    pub tolerance: f64,
    /// Stop when every feedforward step `|l_k| / (|ū_k| + 1)` is below this (default 1e-6).
    pub gradient_tolerance: f64,
    /// Initial Levenberg–Marquardt regularisation μ added to `Q_uu` (default 0: exact Newton).
    pub mu_init: f64,
    /// Below this μ is set to 0 (default 1e-6).
    pub mu_min: f64,
    /// Give up above this μ (default 1e10).
    pub mu_max: f64,
    /// Raise μ after an accepted step shorter than `shrink_below_step` (default true, 0.5).
    pub damp_short_steps: bool,
    pub shrink_below_step: f64,
    /// Include the noise terms in the backward pass and the line search (default true). False
    /// gives deterministic DDP on the same plant.
    pub stochastic: bool,
}

impl Default for IlqgOptions {
    fn default() -> Self {
        IlqgOptions {
            max_iterations: 200,
            tolerance: 1e-6,
            gradient_tolerance: 1e-6,
            mu_init: 0.0,
            mu_min: 1e-6,
            mu_max: 1e10,
            damp_short_steps: true,
            shrink_below_step: 0.5,
            stochastic: true,
        }
    }
}

/// Why the solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// The feedforward step vanished (first-order optimality, projected onto the limits).
    SmallGradient,
    /// An accepted step improved the cost by less than the tolerance.
    SmallImprovement,
    /// The iteration limit was reached.
    MaxIterations,
    /// Regularisation grew past its limit without a descent step.
    RegularizationLimit,
}

impl StopReason {
    /// Whether the stop means a (local) optimum.
    pub fn converged(self) -> bool {
        matches!(
            self,
            StopReason::SmallGradient | StopReason::SmallImprovement
        )
    }
}

/// A locally optimal policy `u = ū + L (x − x̄)` and its figures.
#[derive(Debug, Clone)]
pub struct Solution {
    /// Nominal states `x̄_0 ..= x̄_N`.
    pub x: Vec<DVector<f64>>,
    /// Nominal controls `ū_0 .. ū_{N−1}`.
    pub u: Vec<DVector<f64>>,
    /// Feedback gains `L_k` (m×n).
    pub gains: Vec<DMatrix<f64>>,
    /// Cost of the noise-free nominal trajectory.
    pub cost: f64,
    /// Predicted expected cost `s_0` of the closed-loop policy (equal to `cost` without noise).
    pub expected_cost: f64,
    /// Number of accepted iterations.
    pub iterations: usize,
    pub stop: StopReason,
    pub solve_time: Duration,
    /// Merit (expected cost) after each accepted iteration.
    pub history: Vec<f64>,
}

/// A progress callback.
pub type OnIteration = Box<dyn FnMut(&Progress) + Send>;

/// The state of the solver after an accepted iteration.
#[derive(Debug, Clone, Copy)]
pub struct Progress {
    pub iteration: usize,
    /// The merit (expected cost as the line search sees it) after the step.
    pub merit: f64,
    /// Regularisation in force.
    pub mu: f64,
    /// Accepted step length.
    pub alpha: f64,
}

/// Everything that lives along one trajectory.
struct Trajectory {
    x: Vec<DVector<f64>>,
    u: Vec<DVector<f64>>,
    cost: f64,
    lin: Vec<Linearization>,
    /// The nonzeros of `lin`, for the backward pass's products.
    sparse: Vec<SparseLinearization>,
    derivs: Vec<CostDerivatives>,
}

impl Trajectory {
    fn new(nx: usize, nu: usize, nw: usize, horizon: usize) -> Self {
        Trajectory {
            x: (0..=horizon).map(|_| DVector::zeros(nx)).collect(),
            u: (0..horizon).map(|_| DVector::zeros(nu)).collect(),
            cost: f64::INFINITY,
            lin: (0..horizon)
                .map(|_| Linearization::new(nx, nu, nw))
                .collect(),
            sparse: (0..horizon)
                .map(|_| SparseLinearization::new(nx, nu, nw))
                .collect(),
            derivs: (0..=horizon)
                .map(|_| CostDerivatives::new(nx, nu))
                .collect(),
        }
    }
}

/// Scratch matrices of the backward pass.
struct Backward {
    s_mat: DMatrix<f64>,
    s_vec: DVector<f64>,
    sa: DMatrix<f64>,
    /// `(S A)ᵀ = Aᵀ S` (S is symmetric), so that `Aᵀ S A` is a product by A's columns.
    sat: DMatrix<f64>,
    /// `Lᵀ` and `Q_uxᵀ` (n×m): the value update by contiguous columns.
    lt: DMatrix<f64>,
    xt: DMatrix<f64>,
    sb: DMatrix<f64>,
    scx: DMatrix<f64>,
    scu: DMatrix<f64>,
    sc: DVector<f64>,
    qx: DVector<f64>,
    qu: DVector<f64>,
    qxx: DMatrix<f64>,
    quu: DMatrix<f64>,
    qux: DMatrix<f64>,
    quu_reg: DMatrix<f64>,
    qux_reg: DMatrix<f64>,
    t_mn: DMatrix<f64>,
    t_m: DVector<f64>,
}

/// Why a solve could not start. The iterations themselves never fail: a step that diverges or
/// does not descend is rejected and the regularisation raised, and the solve stops with
/// [`StopReason::RegularizationLimit`] if nothing helps.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IlqgError {
    /// The problem's dimensions differ from those the workspace was built for.
    #[error(
        "problem size (nx, nu, nw, N) = {got:?} differs from the solver's workspace {want:?}: build a new Ilqg"
    )]
    SizeMismatch {
        got: (usize, usize, usize, usize),
        want: (usize, usize, usize, usize),
    },
    /// The initial control sequence has the wrong length.
    #[error("the initial guess has {got} controls, the horizon needs {want}")]
    InitialGuessLength { got: usize, want: usize },
    /// Rolling out the initial guess gave a non-finite state or cost: no nominal to linearise.
    #[error(
        "the initial control sequence makes the plant diverge (non-finite state at step {step} of {horizon}): start from a guess that keeps the plant finite"
    )]
    DivergingInitialGuess { step: usize, horizon: usize },
    /// A warm start needs a previous solve of the same problem size.
    #[error("no previous solution to warm-start from: call try_solve first")]
    NoPreviousSolution,
}

/// Levenberg–Marquardt regularisation μ with Tassa's multiplicative schedule (Tassa, Erez &
/// Todorov 2012): each rise doubles the factor by which μ grows, each fall halves it.
#[derive(Debug, Clone, Copy)]
struct Regularization {
    mu: f64,
    step: f64,
}

impl Regularization {
    fn new(options: &IlqgOptions) -> Self {
        Regularization {
            mu: options.mu_init,
            step: 1.0,
        }
    }

    /// Raises μ; false when it passed `mu_max`.
    fn increase(&mut self, options: &IlqgOptions) -> bool {
        self.step = (self.step * 2.0).max(2.0);
        self.mu = (self.mu * self.step).max(options.mu_min);
        self.mu <= options.mu_max
    }

    /// Lowers μ, to exactly 0 below `mu_min` (pure Newton steps near the optimum).
    fn decrease(&mut self, options: &IlqgOptions) {
        self.step = (self.step / 2.0).min(0.5);
        self.mu = if self.mu * self.step > options.mu_min {
            self.mu * self.step
        } else {
            0.0
        };
    }
}

/// What one backward pass returns: the predicted expected cost `s_0` and the terms of the
/// expected improvement of a step of length α, `−α (dv1 + α dv2)`.
#[derive(Debug, Clone, Copy)]
struct BackwardPass {
    s0: f64,
    dv1: f64,
    dv2: f64,
}

/// An accepted step of the line search.
#[derive(Debug, Clone, Copy)]
struct Step {
    alpha: f64,
    before: f64,
    after: f64,
}

/// Step lengths tried by the line search, longest first.
const ALPHAS: [f64; 9] = [
    1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125, 0.015625, 0.0078125, 0.001,
];

/// The ILQG solver with its preallocated workspace; reuse it for problems of the same size. No
/// iteration allocates: every matrix an iteration touches lives here.
pub struct Ilqg {
    pub options: IlqgOptions,
    /// Called after every accepted iteration (for progress display); must not block.
    pub on_iteration: Option<OnIteration>,
    nominal: Trajectory,
    candidate: Trajectory,
    ff: Vec<DVector<f64>>,
    gains: Vec<DMatrix<f64>>,
    bw: Backward,
    /// `S_{k+1}` of the last backward pass, per step (for the merit).
    value_hessians: Vec<DMatrix<f64>>,
    noise_scratch: DMatrix<f64>,
    dims: (usize, usize, usize, usize),
    /// Whether `nominal` holds the result of a previous solve (for warm starts).
    solved: bool,
}

impl Ilqg {
    /// A solver for `problem`'s dimensions.
    pub fn new(problem: &Problem, options: IlqgOptions) -> Self {
        let (nx, nu, nw, h) = (
            problem.dynamics.nx(),
            problem.dynamics.nu(),
            problem.dynamics.nw(),
            problem.horizon,
        );
        assert!(nu <= MAX_QP, "at most {MAX_QP} controls");
        Ilqg {
            options,
            on_iteration: None,
            nominal: Trajectory::new(nx, nu, nw, h),
            candidate: Trajectory::new(nx, nu, nw, h),
            ff: (0..h).map(|_| DVector::zeros(nu)).collect(),
            gains: (0..h).map(|_| DMatrix::zeros(nu, nx)).collect(),
            bw: Backward::new(nx, nu),
            value_hessians: (0..h).map(|_| DMatrix::zeros(nx, nx)).collect(),
            noise_scratch: DMatrix::zeros(nx, nw),
            dims: (nx, nu, nw, h),
            solved: false,
        }
    }

    /// Solves from the initial control sequence `u_init` (clamped into the limits).
    ///
    /// # Panics
    /// When [`Ilqg::try_solve`] returns an error (a wrong size or a diverging initial guess).
    pub fn solve(&mut self, problem: &Problem, u_init: &[DVector<f64>]) -> Solution {
        self.try_solve(problem, u_init)
            .unwrap_or_else(|e| panic!("ILQG cannot start: {e}"))
    }

    /// Solves from the initial control sequence `u_init` (clamped into the limits), or says why
    /// it cannot start.
    pub fn try_solve(
        &mut self,
        problem: &Problem,
        u_init: &[DVector<f64>],
    ) -> Result<Solution, IlqgError> {
        let start = Instant::now();
        self.check_size(problem)?;
        let horizon = self.dims.3;
        if u_init.len() != horizon {
            return Err(IlqgError::InitialGuessLength {
                got: u_init.len(),
                want: horizon,
            });
        }
        self.solved = false;
        for k in 0..horizon {
            self.nominal.u[k].copy_from(&u_init[k]);
            problem.bounds.clamp(self.nominal.u[k].as_mut_slice());
        }
        self.nominal.x[0].copy_from_slice(&problem.x0);
        if let Err(step) = rollout(problem, &mut self.nominal, None, None, 0.0) {
            return Err(IlqgError::DivergingInitialGuess { step, horizon });
        }
        Ok(self.iterate(problem, start))
    }

    /// Re-solves after the plan has advanced `shift` knots (receding-horizon replanning): the
    /// previous solution is shifted, its last knot repeated, and rolled out from the new
    /// `problem.x0` under its own feedback gains, `u_k = ū_{k+s} + L_{k+s} (x_k − x̄_{k+s})`
    /// (the closed-loop policy of Eq. 9 keeps an unstable plant near the old nominal where an
    /// open-loop replay would drift). The workspace is reused; nothing is allocated but the
    /// returned copy of the solution.
    pub fn resolve_shifted(
        &mut self,
        problem: &Problem,
        shift: usize,
    ) -> Result<Solution, IlqgError> {
        let start = Instant::now();
        self.check_size(problem)?;
        if !self.solved {
            return Err(IlqgError::NoPreviousSolution);
        }
        let horizon = self.dims.3;
        let s = shift.min(horizon);
        shift_knots(&mut self.nominal.u, s);
        shift_knots(&mut self.gains, s);
        shift_knots(&mut self.nominal.x, s);
        for l in &mut self.ff {
            l.fill(0.0);
        }
        self.solved = false;
        self.candidate.x[0].copy_from_slice(&problem.x0);
        let policy = Some((&self.nominal, &self.ff[..], &self.gains[..]));
        if rollout(
            problem,
            &mut self.candidate,
            policy,
            Some(&problem.bounds),
            0.0,
        )
        .is_ok()
        {
            std::mem::swap(&mut self.nominal, &mut self.candidate);
        } else {
            // The old gains do not hold the plant from here: replay the shifted controls.
            self.nominal.x[0].copy_from_slice(&problem.x0);
            if let Err(step) = rollout(problem, &mut self.nominal, None, None, 0.0) {
                return Err(IlqgError::DivergingInitialGuess { step, horizon });
            }
        }
        Ok(self.iterate(problem, start))
    }

    fn check_size(&self, problem: &Problem) -> Result<(), IlqgError> {
        let got = (
            problem.dynamics.nx(),
            problem.dynamics.nu(),
            problem.dynamics.nw(),
            problem.horizon,
        );
        if got != self.dims {
            return Err(IlqgError::SizeMismatch {
                got,
                want: self.dims,
            });
        }
        Ok(())
    }

    /// The ILQG iterations from the rolled-out nominal: backward pass, convergence tests, line
    /// search, regularisation update, until a stop criterion holds.
    fn iterate(&mut self, problem: &Problem, start: Instant) -> Solution {
        let stochastic = self.options.stochastic && self.dims.2 > 0;
        for g in &mut self.gains {
            g.fill(0.0);
        }
        for l in &mut self.ff {
            l.fill(0.0);
        }
        linearize(problem, &mut self.nominal);
        let mut reg = Regularization::new(&self.options);
        let mut iterations = 0;
        let mut history = Vec::with_capacity(self.options.max_iterations);
        let mut expected = self.nominal.cost;
        let mut stop = StopReason::MaxIterations;
        let mut finish_after_backward = false;

        for _ in 0..self.options.max_iterations {
            let Some(pass) = self.regularized_backward_pass(problem, &mut reg, stochastic) else {
                stop = StopReason::RegularizationLimit;
                break;
            };
            expected = pass.s0;
            if finish_after_backward {
                stop = StopReason::SmallImprovement;
                break;
            }
            if self.feedforward_gradient() < self.options.gradient_tolerance {
                stop = StopReason::SmallGradient;
                break;
            }
            // The merit of the current nominal under the new gains, for a like-for-like comparison.
            let merit_now = self.merit(problem, stochastic, false);
            let trusted_mu = TRUSTED_MU * self.value_scale();
            if self.predicted_converged(&pass, reg.mu, trusted_mu, merit_now) {
                stop = StopReason::SmallImprovement;
                break;
            }
            match self.line_search(problem, &pass, merit_now, stochastic) {
                Some(step) => {
                    std::mem::swap(&mut self.nominal, &mut self.candidate);
                    linearize(problem, &mut self.nominal);
                    iterations += 1;
                    history.push(step.after);
                    if let Some(cb) = self.on_iteration.as_mut() {
                        cb(&Progress {
                            iteration: iterations,
                            merit: step.after,
                            mu: reg.mu,
                            alpha: step.alpha,
                        });
                    }
                    self.update_regularization(&mut reg, step.alpha);
                    // One more backward pass so that the gains and s_0 belong to this nominal.
                    finish_after_backward = self.step_converged(&step, reg.mu, trusted_mu);
                }
                None => {
                    if !reg.increase(&self.options) {
                        stop = StopReason::RegularizationLimit;
                        break;
                    }
                }
            }
        }
        self.solved = true;
        Solution {
            x: self.nominal.x.clone(),
            u: self.nominal.u.clone(),
            gains: self.gains.clone(),
            cost: self.nominal.cost,
            expected_cost: if stochastic {
                expected
            } else {
                self.nominal.cost
            },
            iterations,
            stop,
            solve_time: start.elapsed(),
            history,
        }
    }

    /// Backward passes with μ raised until every `Q_uu` is positive definite; `None` when μ
    /// passes its limit first.
    fn regularized_backward_pass(
        &mut self,
        problem: &Problem,
        reg: &mut Regularization,
        stochastic: bool,
    ) -> Option<BackwardPass> {
        loop {
            if let Some(pass) = self.backward_pass(problem, reg.mu, stochastic) {
                return Some(pass);
            }
            if !reg.increase(&self.options) {
                return None;
            }
        }
    }

    /// The largest feedforward step relative to its control, `max |l_k| / (|ū_k| + 1)`: zero at
    /// a first-order optimum (projected onto the limits, since clamped components get `l = 0`).
    fn feedforward_gradient(&self) -> f64 {
        self.ff
            .iter()
            .zip(&self.nominal.u)
            .flat_map(|(l, u)| {
                l.iter()
                    .zip(u.iter())
                    .map(|(l, u)| l.abs() / (u.abs() + 1.0))
            })
            .fold(0.0, f64::max)
    }

    /// Nothing left to gain at first order: the predicted improvement of an (almost) undamped
    /// Newton step is negligible against the merit.
    fn predicted_converged(
        &self,
        pass: &BackwardPass,
        mu: f64,
        trusted_mu: f64,
        merit: f64,
    ) -> bool {
        mu <= trusted_mu && -(pass.dv1 + pass.dv2) < self.options.tolerance * merit.abs()
    }

    /// A small improvement means convergence only after a long step with little
    /// regularisation; a short, heavily damped step improves little anywhere.
    fn step_converged(&self, step: &Step, mu: f64, trusted_mu: f64) -> bool {
        let trusted = step.alpha >= self.options.shrink_below_step && mu <= trusted_mu;
        trusted
            && (step.before - step.after) / step.after.abs().max(1e-300) < self.options.tolerance
    }

    /// After an accepted step of length α: a long step means the local model was trusted, so μ
    /// falls (Tassa's schedule); only a short step helping means the quadratic model overshoots
    /// (typically in the stiffness, whose effect is bilinear), and the next Newton step is damped.
    fn update_regularization(&self, reg: &mut Regularization, alpha: f64) {
        if alpha >= self.options.shrink_below_step || !self.options.damp_short_steps {
            reg.decrease(&self.options);
        } else {
            // No limit check here: a rejected step checks it.
            let _ = reg.increase(&self.options);
        }
    }

    /// Backtracking line search on the merit: rolls the policy `ū + α l + L (x − x̄)` out into
    /// `candidate` for decreasing α and accepts the first that improves the merit by a positive
    /// fraction of the predicted improvement `−α (dv1 + α dv2)` (Armijo-like).
    fn line_search(
        &mut self,
        problem: &Problem,
        pass: &BackwardPass,
        merit_now: f64,
        stochastic: bool,
    ) -> Option<Step> {
        for alpha in ALPHAS {
            self.candidate.x[0].copy_from_slice(&problem.x0);
            let policy = Some((&self.nominal, &self.ff[..], &self.gains[..]));
            if rollout(
                problem,
                &mut self.candidate,
                policy,
                Some(&problem.bounds),
                alpha,
            )
            .is_err()
            {
                continue;
            }
            let merit_new = self.merit(problem, stochastic, true);
            let predicted = -alpha * (pass.dv1 + alpha * pass.dv2);
            let actual = merit_now - merit_new;
            let ratio = if predicted > 0.0 {
                actual / predicted
            } else {
                actual.signum()
            };
            if actual > 0.0 && ratio > 1e-4 {
                return Some(Step {
                    alpha,
                    before: merit_now,
                    after: merit_new,
                });
            }
        }
        None
    }

    /// The line-search merit of the nominal (or the candidate): its cost plus the noise cost
    /// `Σ_k ½ Σ_i c_iᵀ S_{k+1} c_i` with the value Hessians `S` of the last backward pass frozen.
    /// Its gradient is exactly the noise part of the backward pass's `Q_x`, `Q_u` (the `Cxᵀ S c`,
    /// `Cuᵀ S c` terms), so an ILQG step is a descent direction for it. The fully propagated
    /// expected cost ([`crate::core::solver::moments::expected_cost`]) also moves with the linearisation itself, which
    /// ILQG's first-order step does not see (DESIGN §4), and makes a poor merit.
    fn merit(&mut self, problem: &Problem, stochastic: bool, candidate: bool) -> f64 {
        let traj = if candidate {
            &self.candidate
        } else {
            &self.nominal
        };
        if !stochastic {
            return traj.cost;
        }
        let g = &mut self.noise_scratch;
        let mut noise = 0.0;
        for k in 0..problem.horizon {
            problem
                .dynamics
                .noise_gain(k, traj.x[k].as_slice(), traj.u[k].as_slice(), g);
            let s = &self.value_hessians[k];
            for i in 0..g.ncols() {
                let c = g.column(i);
                let mut q = 0.0;
                for a in 0..c.len() {
                    q += c[a] * s.column(a).dot(&c);
                }
                noise += 0.5 * q;
            }
        }
        traj.cost + noise
    }

    /// Mean magnitude of the diagonal of the value Hessian at the first knot of the last backward
    /// pass: the scale against which the regularisation μ is large or small.
    fn value_scale(&self) -> f64 {
        let s = &self.bw.s_mat;
        let n = s.nrows().max(1);
        (0..s.nrows()).map(|i| s[(i, i)].abs()).sum::<f64>() / n as f64
    }

    /// One backward pass (DESIGN §4) at the nominal with regularisation `mu`: per knot, from the
    /// last, the Q-function, the policy from the (box) QP, the value update. `None` when a
    /// `Q_uu` is not positive definite.
    fn backward_pass(
        &mut self,
        problem: &Problem,
        mu: f64,
        stochastic: bool,
    ) -> Option<BackwardPass> {
        let horizon = self.dims.3;
        let bw = &mut self.bw;
        let traj = &self.nominal;
        let term = &traj.derivs[horizon];
        copy(&term.lxx, &mut bw.s_mat);
        bw.s_vec.copy_from(&term.lx);
        let mut pass = BackwardPass {
            s0: problem.cost.terminal(traj.x[horizon].as_slice()),
            dv1: 0.0,
            dv2: 0.0,
        };
        for k in (0..horizon).rev() {
            if stochastic {
                // Only the stochastic merit reads them.
                copy(&bw.s_mat, &mut self.value_hessians[k]);
            }
            let q0 = bw.q_function(problem, traj, k, stochastic) + pass.s0;
            bw.regularize(&traj.sparse[k], &traj.lin[k], mu);
            if !bw.policy(
                &problem.bounds,
                &traj.u[k],
                &mut self.ff[k],
                &mut self.gains[k],
            ) {
                return None;
            }
            let (lqu, lquul) = bw.value_update(&self.ff[k], &self.gains[k]);
            pass.s0 = q0 + lqu + 0.5 * lquul;
            pass.dv1 += lqu;
            pass.dv2 += 0.5 * lquul;
        }
        Some(pass)
    }

    /// The current gains (valid after [`Ilqg::solve`]).
    pub fn gains(&self) -> &[DMatrix<f64>] {
        &self.gains
    }
}

/// Moves every knot `s` places earlier and repeats the last knot into the `s` freed places
/// (in place: no allocation).
fn shift_knots<T: Clone>(knots: &mut [T], s: usize) {
    let n = knots.len();
    if s == 0 || n == 0 {
        return;
    }
    let s = s.min(n - 1);
    knots.rotate_left(s);
    let (head, tail) = knots.split_at_mut(n - s);
    for t in tail {
        t.clone_from(&head[n - s - 1]);
    }
}

impl Backward {
    fn new(nx: usize, nu: usize) -> Self {
        Backward {
            s_mat: DMatrix::zeros(nx, nx),
            s_vec: DVector::zeros(nx),
            sa: DMatrix::zeros(nx, nx),
            sat: DMatrix::zeros(nx, nx),
            lt: DMatrix::zeros(nx, nu),
            xt: DMatrix::zeros(nx, nu),
            sb: DMatrix::zeros(nx, nu),
            scx: DMatrix::zeros(nx, nx),
            scu: DMatrix::zeros(nx, nu),
            sc: DVector::zeros(nx),
            qx: DVector::zeros(nx),
            qu: DVector::zeros(nu),
            qxx: DMatrix::zeros(nx, nx),
            quu: DMatrix::zeros(nu, nu),
            qux: DMatrix::zeros(nu, nx),
            quu_reg: DMatrix::zeros(nu, nu),
            qux_reg: DMatrix::zeros(nu, nx),
            t_mn: DMatrix::zeros(nu, nx),
            t_m: DVector::zeros(nu),
        }
    }

    /// The Q-function of knot `k` (DESIGN §4) from the value `(S, s)` of knot `k + 1`, into
    /// `qx, qu, qxx, quu, qux`; returns its constant term `Δ l + ½ Σ c_iᵀ S c_i` (without `s`).
    /// The products take A, B, Cx, Cu by their nonzeros (see `sparse`): n·nnz, not n³.
    fn q_function(
        &mut self,
        problem: &Problem,
        traj: &Trajectory,
        k: usize,
        stochastic: bool,
    ) -> f64 {
        let (lin, d, sp) = (&traj.lin[k], &traj.derivs[k], &traj.sparse[k]);
        let mut q0 = problem
            .cost
            .running(k, traj.x[k].as_slice(), traj.u[k].as_slice());
        self.qx.copy_from(&d.lx);
        sp.a.tr_mul_vec_add(1.0, self.s_vec.as_slice(), self.qx.as_mut_slice());
        self.qu.copy_from(&d.lu);
        sp.b.tr_mul_vec_add(1.0, self.s_vec.as_slice(), self.qu.as_mut_slice());
        sp.a.right_mul(&self.s_mat, &mut self.sa);
        sp.b.right_mul(&self.s_mat, &mut self.sb);
        copy(&d.lxx, &mut self.qxx);
        transpose(&self.sa, &mut self.sat);
        sp.a.right_mul_add(&self.sat, &mut self.qxx);
        copy(&d.luu, &mut self.quu);
        sp.b.tr_mul_add(1.0, &self.sb, &mut self.quu);
        copy(&d.lux, &mut self.qux);
        sp.b.tr_mul_add(1.0, &self.sa, &mut self.qux);
        if stochastic && lin.noise != NoiseKind::None {
            for i in 0..lin.c.ncols() {
                self.sc.gemv(1.0, &self.s_mat, &lin.c.column(i), 0.0);
                q0 += 0.5 * lin.c.column(i).dot(&self.sc);
                if lin.noise == NoiseKind::Dependent {
                    let (cx, cu) = (&sp.cx[i], &sp.cu[i]);
                    cx.tr_mul_vec_add(1.0, self.sc.as_slice(), self.qx.as_mut_slice());
                    cu.tr_mul_vec_add(1.0, self.sc.as_slice(), self.qu.as_mut_slice());
                    cx.right_mul(&self.s_mat, &mut self.scx);
                    cu.right_mul(&self.s_mat, &mut self.scu);
                    transpose(&self.scx, &mut self.sat);
                    cx.right_mul_add(&self.sat, &mut self.qxx);
                    cu.tr_mul_add(1.0, &self.scu, &mut self.quu);
                    cu.tr_mul_add(1.0, &self.scx, &mut self.qux);
                }
            }
        }
        q0
    }

    /// Regularisation on the value function (Tassa, Erez & Todorov 2012): S + μ I in the
    /// control terms, into `quu_reg`, `qux_reg`. As μ grows the gains tend to −(BᵀB)⁻¹BᵀA, which
    /// cancels state deviations, rather than to zero (open loop), so the line search stays
    /// meaningful in an unstable field. The value update uses the unregularised Q.
    fn regularize(&mut self, sp: &SparseLinearization, lin: &Linearization, mu: f64) {
        copy(&self.quu, &mut self.quu_reg);
        copy(&self.qux, &mut self.qux_reg);
        if mu > 0.0 {
            sp.b.tr_mul_add(mu, &lin.b, &mut self.quu_reg);
            sp.b.tr_mul_add(mu, &lin.a, &mut self.qux_reg);
            for j in 0..self.quu_reg.nrows() {
                // A trace of control-space damping for controls that do not move the state.
                self.quu_reg[(j, j)] += mu * 1e-6;
            }
        }
    }

    /// The policy `δu = l + L δx` of the knot: the feedforward step `l` from the box QP
    /// `min ½ lᵀ Q_uu l + Q_uᵀ l` over `lower − ū ≤ l ≤ upper − ū` on the regularised `Q_uu`
    /// (projected Newton, Tassa, Mansard & Todorov 2014), warm-started at the previous `l`; the
    /// gains `L = −Q_uu⁻¹ Q_ux` on its free components, zero on the clamped ones. Without limits
    /// the QP is one Newton step and is not run. (Skipping it also whenever the Newton step
    /// happens to land inside a finite box would be the same mathematics, but the QP reaches
    /// that point along another sequence of roundings; the stochastic single joint, whose
    /// optimum is flat in the stiffness, then settles 3 % away in expected cost.) False when
    /// `Q_uu` is not positive definite.
    fn policy(
        &self,
        bounds: &Bounds,
        u: &DVector<f64>,
        l: &mut DVector<f64>,
        gain: &mut DMatrix<f64>,
    ) -> bool {
        let nu = u.len();
        let quu = &self.quu_reg;
        let h = |i: usize, j: usize| quu[(i, j)];
        let mut lower = [0.0; MAX_QP];
        let mut upper = [0.0; MAX_QP];
        for j in 0..nu {
            lower[j] = bounds.lower[j] - u[j];
            upper[j] = bounds.upper[j] - u[j];
        }
        let unbounded = (0..nu).all(|j| lower[j] == f64::NEG_INFINITY && upper[j] == f64::INFINITY);
        let (x, free, factor) = if unbounded {
            let all = [0, 1, 2, 3, 4, 5, 6, 7];
            match newton_step(h, self.qu.as_slice(), &all[..nu]) {
                None => return false,
                Some((x, factor)) => (x, [true; MAX_QP], Some(factor)),
            }
        } else {
            let qp = solve_box_qp(
                h,
                self.qu.as_slice(),
                &lower[..nu],
                &upper[..nu],
                l.as_slice(),
            );
            if qp.status == QpStatus::NotPositiveDefinite {
                return false;
            }
            (qp.x, qp.free, qp.factor)
        };
        l.as_mut_slice().copy_from_slice(&x[..nu]);
        gain.as_mut_slice().fill(0.0);
        if let Some(factor) = factor {
            let mut idx = [0usize; MAX_QP];
            let mut nfree = 0;
            for j in (0..nu).filter(|&j| free[j]) {
                idx[nfree] = j;
                nfree += 1;
            }
            let mut col = [0.0; MAX_QP];
            for c in 0..gain.ncols() {
                for (a, &j) in idx[..nfree].iter().enumerate() {
                    col[a] = self.qux_reg[(j, c)];
                }
                factor.solve(&mut col[..nfree]);
                for (a, &j) in idx[..nfree].iter().enumerate() {
                    gain[(j, c)] = -col[a];
                }
            }
        }
        true
    }

    /// Value function update (Tassa 2012 form, valid with regularisation and clamping):
    /// `s = Q_x + Lᵀ Q_uu l + Lᵀ Q_u + Q_uxᵀ l`, `S = Q_xx + Lᵀ Q_uu L + Lᵀ Q_ux + Q_uxᵀ L`.
    /// Returns `(lᵀ Q_u, lᵀ Q_uu l)` for `s_0` and the expected improvement.
    fn value_update(&mut self, l: &DVector<f64>, gain: &DMatrix<f64>) -> (f64, f64) {
        let nu = l.len();
        self.t_m.gemv(1.0, &self.quu, l, 0.0); // Q_uu l
        let lqu = l.dot(&self.qu);
        let lquul = l.dot(&self.t_m);
        self.t_m += &self.qu; // Q_uu l + Q_u
        self.s_vec.copy_from(&self.qx);
        self.s_vec.gemv_tr(1.0, gain, &self.t_m, 1.0);
        self.s_vec.gemv_tr(1.0, &self.qux, l, 1.0);
        copy(&self.qux, &mut self.t_mn);
        self.t_mn.gemm(1.0, &self.quu, gain, 1.0); // Q_uu L + Q_ux
        // S = Q_xx + Lᵀ (Q_uu L + Q_ux) + Q_uxᵀ L as 2m rank-one updates, each an axpy on
        // contiguous columns of the transposed thin factors (nalgebra's transposed products
        // are plain dot loops).
        transpose(gain, &mut self.lt);
        transpose(&self.qux, &mut self.xt);
        let n = self.s_mat.nrows();
        let (gd, td) = (gain.as_slice(), self.t_mn.as_slice());
        let (ltd, xtd) = (self.lt.as_slice(), self.xt.as_slice());
        let sd = self.s_mat.as_mut_slice();
        sd.copy_from_slice(self.qxx.as_slice());
        for j in 0..n {
            let col = &mut sd[j * n..(j + 1) * n];
            for r in 0..nu {
                let (t, g) = (td[j * nu + r], gd[j * nu + r]);
                let (lr, xr) = (&ltd[r * n..(r + 1) * n], &xtd[r * n..(r + 1) * n]);
                for ((s, l), x) in col.iter_mut().zip(lr).zip(xr) {
                    *s += l * t + x * g;
                }
            }
        }
        // Symmetric against round-off: the average of the two triangles.
        for j in 0..n {
            for i in j + 1..n {
                let m = 0.5 * (sd[j * n + i] + sd[i * n + j]);
                sd[j * n + i] = m;
                sd[i * n + j] = m;
            }
        }
        (lqu, lquul)
    }
}

/// The unconstrained Newton step `x = −H⁻¹ g` with the Cholesky factor of `H` over the indices
/// `idx` (all of them), or `None` when `H` is not positive definite.
fn newton_step(
    h: impl Fn(usize, usize) -> f64 + Copy,
    g: &[f64],
    idx: &[usize],
) -> Option<([f64; MAX_QP], SmallCholesky)> {
    let factor = SmallCholesky::new(h, idx)?;
    let mut x = [0.0; MAX_QP];
    for (a, &i) in idx.iter().enumerate() {
        x[a] = -g[i];
    }
    factor.solve(&mut x[..idx.len()]);
    Some((x, factor))
}

/// `dst = src` for matrices of one size, as one `memcpy` (nalgebra's `copy_from` goes element by
/// element through a generic iterator, which showed in profiles of the 42-dimensional delay
/// problem).
fn copy(src: &DMatrix<f64>, dst: &mut DMatrix<f64>) {
    dst.as_mut_slice().copy_from_slice(src.as_slice());
}

/// `dst = srcᵀ` on the column-major storage (see [`copy`]).
fn transpose(src: &DMatrix<f64>, dst: &mut DMatrix<f64>) {
    let (r, c) = (src.nrows(), src.ncols());
    debug_assert_eq!((dst.nrows(), dst.ncols()), (c, r));
    let (sd, dd) = (src.as_slice(), dst.as_mut_slice());
    for j in 0..c {
        for (i, &v) in sd[j * r..(j + 1) * r].iter().enumerate() {
            dd[i * c + j] = v;
        }
    }
}

/// A policy to roll out: the nominal it was made around, the feedforward steps and the gains.
type Policy<'a> = (&'a Trajectory, &'a [DVector<f64>], &'a [DMatrix<f64>]);

/// Rolls `traj` forward from `traj.x[0]`. With a policy `(nominal, l, L)` the controls are
/// `clamp(ū + α l + L (x − x̄))`; without, `traj.u` is used as it is. On divergence (a non-finite
/// state or cost) returns the step at which it happened.
fn rollout(
    problem: &Problem,
    traj: &mut Trajectory,
    policy: Option<Policy>,
    bounds: Option<&Bounds>,
    alpha: f64,
) -> Result<(), usize> {
    let mut cost = 0.0;
    for k in 0..problem.horizon {
        if let Some((nom, ff, gains)) = policy {
            let (xs, us) = (&mut traj.x, &mut traj.u);
            let uk = &mut us[k];
            uk.copy_from(&nom.u[k]);
            uk.axpy(alpha, &ff[k], 1.0);
            // u += L (x − x̄), without a temporary.
            for r in 0..uk.len() {
                let mut acc = 0.0;
                for c in 0..xs[k].len() {
                    acc += gains[k][(r, c)] * (xs[k][c] - nom.x[k][c]);
                }
                uk[r] += acc;
            }
            if let Some(b) = bounds {
                b.clamp(uk.as_mut_slice());
            }
        }
        let (head, tail) = traj.x.split_at_mut(k + 1);
        problem.dynamics.step(
            k,
            head[k].as_slice(),
            traj.u[k].as_slice(),
            tail[0].as_mut_slice(),
        );
        cost += problem
            .cost
            .running(k, head[k].as_slice(), traj.u[k].as_slice());
        if !tail[0].iter().all(|v| v.is_finite()) {
            return Err(k + 1);
        }
    }
    cost += problem.cost.terminal(traj.x[problem.horizon].as_slice());
    traj.cost = cost;
    if cost.is_finite() {
        Ok(())
    } else {
        Err(problem.horizon)
    }
}

/// Linearises the dynamics and differentiates the cost along `traj`. Knots are independent: when
/// the model says a linearisation is expensive
/// ([`Dynamics::parallel_linearization`](crate::core::dynamics::Dynamics::parallel_linearization)) they
/// are linearised in parallel, otherwise in order (thread hand-offs would cost more than they
/// save, and a sequential pass allocates nothing). Each knot's result is computed the same way
/// either way, so the solution does not depend on the thread count.
fn linearize(problem: &Problem, traj: &mut Trajectory) {
    use rayon::prelude::*;
    let h = problem.horizon;
    let (xs, us) = (&traj.x, &traj.u);
    let knot = |k: usize,
                lin: &mut Linearization,
                sparse: &mut SparseLinearization,
                d: &mut CostDerivatives| {
        let (x, u) = (xs[k].as_slice(), us[k].as_slice());
        problem.dynamics.linearize(k, x, u, lin);
        sparse.assign(lin);
        problem.cost.running_derivatives(k, x, u, d);
    };
    if problem.dynamics.parallel_linearization() {
        traj.lin[..h]
            .par_iter_mut()
            .zip(traj.sparse[..h].par_iter_mut())
            .zip(traj.derivs[..h].par_iter_mut())
            .enumerate()
            .with_min_len(8)
            .for_each(|(k, ((lin, sparse), d))| knot(k, lin, sparse, d));
    } else {
        for (k, ((lin, sparse), d)) in traj.lin[..h]
            .iter_mut()
            .zip(traj.sparse[..h].iter_mut())
            .zip(traj.derivs[..h].iter_mut())
            .enumerate()
        {
            knot(k, lin, sparse, d);
        }
    }
    problem
        .cost
        .terminal_derivatives(xs[h].as_slice(), &mut traj.derivs[h]);
}
