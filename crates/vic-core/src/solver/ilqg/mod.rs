//! Iterative LQG for stochastic plants with state- and control-dependent noise (Todorov & Li 2005;
//! the paper's Eq. 8–10 and 14), with box-constrained controls by projected Newton (Tassa,
//! Mansard & Todorov 2014), adaptive Levenberg–Marquardt regularisation and a backtracking line
//! search.
//!
//! The line search compares *expected* costs when the plant is stochastic: the nominal cost plus
//! the second-order noise cost of the candidate under the new feedback gains
//! ([`crate::solver::moments::expected_cost`]). The deterministic cost alone would reject the very steps the noise
//! terms of the backward pass ask for.

use super::boxqp::MAX_QP;
use super::sparse::SparseLinearization;
use super::{Bounds, Problem};
use crate::cost::CostDerivatives;
use crate::dense::zero;
use crate::dynamics::{Linearization, NoiseKind, StateSupport};
use nalgebra::allocator::Allocator;
use nalgebra::{DMatrix, DVector, DefaultAllocator, Dim, OMatrix};
use serde::{Deserialize, Serialize};
use std::time::{Duration, Instant};

mod backward;
mod convergence;
mod held;
mod knot;
mod options;
mod policy;
mod resolve;
mod rollout;
mod search;

pub use convergence::Convergence;
pub use options::IlqgOptions;

use backward::Backward;
use rollout::{ensure_linearized, rollout};

/// Regularisation, relative to the mean diagonal of the value Hessian `S_0`, below which the
/// backward pass's model is trusted for a convergence verdict.
const TRUSTED_MU: f64 = 1e-3;

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
    /// The stop tests' values at the plan (`None` for a plan no ILQG iteration produced, or
    /// when not even the first backward pass completed).
    pub convergence: Option<Convergence>,
}

impl Solution {
    /// No plan yet: what [`Ilqg::try_solve_into`] fills.
    pub fn empty() -> Self {
        Solution {
            x: Vec::new(),
            u: Vec::new(),
            gains: Vec::new(),
            cost: f64::INFINITY,
            expected_cost: f64::INFINITY,
            iterations: 0,
            stop: StopReason::MaxIterations,
            solve_time: Duration::ZERO,
            history: Vec::new(),
            convergence: None,
        }
    }
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
    /// The running cost of every knot and the terminal cost, from the rollout (the backward
    /// pass's constant terms).
    running: Vec<f64>,
    terminal: f64,
    lin: Vec<Linearization>,
    /// The nonzeros of `lin`, for the backward pass's products; filled only for the plants
    /// whose Jacobians the backward pass does not read in place ([`backward::reads_in_place`]).
    sparse: Vec<SparseLinearization>,
    derivs: Vec<CostDerivatives>,
    /// Whether `lin`, `sparse` and `derivs` belong to `x` and `u` (set by [`rollout::linearize`] and
    /// by a complete fused rollout, cleared when a rollout starts).
    linearized: bool,
    /// Whether every `lin[k]` holds a linearisation of this solve's plant at knot `k` (from any
    /// state), or of any plant with the same support, so that the plant may refill it (`refill`
    /// of [`Dynamics::linearize_with`]): set by a complete linearisation, kept when the next solve's plant declares
    /// the same support (it then writes every entry the support leaves open, and the others
    /// are fixed by it), cleared otherwise (another solve may bring another plant).
    ///
    /// [`Dynamics::linearize_with`]: crate::dynamics::Dynamics::linearize_with
    relinearizable: bool,
    /// Whether every `derivs[k]` holds the derivatives of this solve's cost at knot `k` (from
    /// any state), so that [`Cost::running_derivatives_again`] may refill them: set by a
    /// complete linearisation, cleared when a solve starts (another solve may bring another
    /// cost).
    ///
    /// [`Cost::running_derivatives_again`]: crate::cost::Cost::running_derivatives_again
    differentiated: bool,
    /// Where the plant's `A` and `Cx_i` can be nonzero, when it says
    /// ([`Dynamics::structure`](crate::dynamics::Dynamics::structure)): the
    /// nonzeros are then read there only.
    support: StateSupport,
    supported: bool,
    /// Whether the plant's knots are linearised in parallel
    /// ([`Structure::parallel_linearization`](crate::dynamics::Structure)), read with its
    /// support.
    parallel: bool,
    /// The support of the last solve's plant (kept to compare with the next one's).
    last_support: StateSupport,
    /// Where the cost's `l_xx` can be nonzero ([`Cost::hessian_support`], all of the state
    /// when the cost does not say).
    hessian: std::ops::Range<usize>,
}

impl Trajectory {
    fn new(nx: usize, nu: usize, nw: usize, horizon: usize) -> Self {
        Trajectory {
            x: (0..=horizon).map(|_| DVector::zeros(nx)).collect(),
            u: (0..horizon).map(|_| DVector::zeros(nu)).collect(),
            cost: f64::INFINITY,
            running: vec![0.0; horizon],
            terminal: 0.0,
            lin: (0..horizon)
                .map(|_| Linearization::new(nx, nu, nw))
                .collect(),
            sparse: (0..horizon)
                .map(|_| SparseLinearization::new(nx, nu, nw))
                .collect(),
            derivs: (0..=horizon)
                .map(|_| CostDerivatives::new(nx, nu))
                .collect(),
            linearized: false,
            relinearizable: false,
            differentiated: false,
            support: StateSupport::with_capacity(nx, nu),
            supported: false,
            parallel: true,
            last_support: StateSupport::with_capacity(nx, nu),
            hessian: 0..nx,
        }
    }

    /// The rows where the model's noise columns can be nonzero (all of them unless its support
    /// says): those of the value Hessians the stochastic merit reads.
    fn noise_rows(&self) -> std::ops::Range<usize> {
        if self.supported {
            self.support.c.clone()
        } else {
            0..self.x[0].len()
        }
    }

    /// Forgets what belonged to the last solve's plant and cost and reads this one's support
    /// (kept only if it fits the plant's size). The linearisations stay refillable when the
    /// last plant declared the same support: the delayed planner's solves and replans then
    /// skip clearing 42² entries of `A` and of each noise Jacobian at every knot (a twentieth
    /// of a noisy delayed plan).
    fn start_solve(&mut self, problem: &Problem) {
        let (nx, nu) = (problem.dynamics.nx(), problem.dynamics.nu());
        let refillable = self.relinearizable && self.supported;
        std::mem::swap(&mut self.support, &mut self.last_support);
        let structure = problem.dynamics.structure(Some(&mut self.support));
        self.supported = structure.supported && self.support.fits(nx, nu);
        self.parallel = structure.parallel_linearization;
        self.relinearizable = refillable && self.supported && self.support == self.last_support;
        self.make_room(nx, nu);
        self.differentiated = false;
        self.hessian = match problem.cost.hessian_support() {
            Some(r) if r.start <= r.end && r.end <= nx => r,
            _ => 0..nx,
        };
    }
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
    /// A given control has the wrong number of components.
    #[error("control {knot} has {got} components, the plant takes {want}")]
    ControlSize {
        knot: usize,
        got: usize,
        want: usize,
    },
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
    /// `S_{k+1}` of the last stochastic backward pass, per step (for the merit), in the rows
    /// and columns where the noise acts (`Trajectory::noise_rows`).
    value_hessians: Vec<DMatrix<f64>>,
    noise_scratch: DMatrix<f64>,
    dims: (usize, usize, usize, usize),
    /// Whether `nominal` holds the result of a previous solve (for warm starts).
    solved: bool,
    /// Iterations of a held first solve, counted on in the progress of the free one.
    iterations_before: usize,
    /// The regularisation and noise switch of the last backward pass of the last solve.
    last_pass: (f64, bool),
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
            nominal: Trajectory::with_room(problem, h),
            candidate: Trajectory::with_room(problem, h),
            ff: (0..h).map(|_| DVector::zeros(nu)).collect(),
            gains: (0..h).map(|_| DMatrix::zeros(nu, nx)).collect(),
            bw: Backward::new(nx, nu),
            value_hessians: (0..h).map(|_| DMatrix::zeros(nx, nx)).collect(),
            noise_scratch: DMatrix::zeros(nx, nw),
            dims: (nx, nu, nw, h),
            solved: false,
            iterations_before: 0,
            last_pass: (0.0, false),
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
        let mut out = Solution::empty();
        self.try_solve_into(problem, u_init, &mut out)?;
        Ok(out)
    }

    /// [`Ilqg::try_solve`] into `out`, reusing its storage when it holds a solution of the same
    /// size (a loop of solves then allocates nothing: the reach's 301 vectors and matrices per
    /// returned solution would otherwise cost a noticeable share of its solve in `malloc` and
    /// `free`). On an error `out` is left as it was.
    pub fn try_solve_into(
        &mut self,
        problem: &Problem,
        u_init: &[DVector<f64>],
        out: &mut Solution,
    ) -> Result<(), IlqgError> {
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
        self.nominal.start_solve(problem);
        self.candidate.start_solve(problem);
        for k in 0..horizon {
            self.nominal.u[k].copy_from(&u_init[k]);
            problem.bounds.clamp(self.nominal.u[k].as_mut_slice());
        }
        self.replay(problem)?;
        self.iterate(problem, start, out);
        Ok(())
    }

    /// Rolls the nominal's controls out open loop from `problem.x0`, linearising on the way.
    fn replay(&mut self, problem: &Problem) -> Result<(), IlqgError> {
        self.nominal.x[0].copy_from_slice(&problem.x0);
        let inf = f64::INFINITY;
        rollout(problem, &mut self.nominal, None, None, 0.0, inf, true).map_err(|step| {
            IlqgError::DivergingInitialGuess {
                step,
                horizon: self.dims.3,
            }
        })
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
    fn iterate(&mut self, problem: &Problem, start: Instant, out: &mut Solution) {
        let stochastic = self.options.stochastic && self.dims.2 > 0;
        for g in &mut self.gains {
            zero(g);
        }
        for l in &mut self.ff {
            zero(l);
        }
        ensure_linearized(problem, &mut self.nominal);
        let mut reg = Regularization::new(&self.options);
        let mut iterations = 0;
        let history = &mut out.history;
        history.clear();
        // At most one allocation, whatever the number of iterations.
        history.reserve(self.options.max_iterations);
        let mut expected = self.nominal.cost;
        let mut stop = StopReason::MaxIterations;
        let mut finish_after_backward = false;
        let mut record = Convergence::untested(&self.options, reg.mu);
        // Which step length to linearise on the way: in a deterministic solve, the one accepted
        // last (the next step likely has it too). Not in stochastic solves: there a full step
        // after a full step is mostly rejected on the iCub elbow and the VSA arm (μ falls after
        // a full step and the next one overshoots).
        let mut fuse = (!stochastic).then_some(1.0);

        for _ in 0..self.options.max_iterations {
            let Some(pass) = self.regularized_backward_pass(problem, &mut reg, stochastic) else {
                stop = StopReason::RegularizationLimit;
                break;
            };
            expected = pass.s0;
            record.feedforward_step = self.feedforward_gradient();
            if finish_after_backward {
                stop = StopReason::SmallImprovement;
                break;
            }
            if record.gradient_met() {
                stop = StopReason::SmallGradient;
                break;
            }
            // The merit of the current nominal under the new gains, for a like-for-like comparison.
            let merit_now = self.merit(problem, stochastic, false);
            let trusted_mu = TRUSTED_MU * self.value_scale();
            if record.predicted(&pass, reg.mu, trusted_mu, merit_now) {
                stop = StopReason::SmallImprovement;
                break;
            }
            let step = self.line_search(problem, &pass, merit_now, stochastic, fuse);
            fuse = step.as_ref().map(|s| s.alpha).filter(|_| !stochastic);
            match step {
                Some(step) => {
                    std::mem::swap(&mut self.nominal, &mut self.candidate);
                    ensure_linearized(problem, &mut self.nominal);
                    iterations += 1;
                    history.push(step.after);
                    self.notify(iterations, step.after, reg.mu, step.alpha);
                    self.update_regularization(&mut reg, step.alpha);
                    // One more backward pass so that the gains and s_0 belong to this nominal.
                    finish_after_backward = record.achieved(&step, reg.mu, trusted_mu);
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
        self.last_pass = (reg.mu, stochastic);
        let expected_cost = if stochastic {
            expected
        } else {
            self.nominal.cost
        };
        copy_knots(&mut out.x, &self.nominal.x);
        copy_knots(&mut out.u, &self.nominal.u);
        copy_knots(&mut out.gains, &self.gains);
        out.cost = self.nominal.cost;
        out.expected_cost = expected_cost;
        out.iterations = iterations;
        out.stop = stop;
        out.convergence = record.reported();
        out.solve_time = start.elapsed();
    }

    /// Tells the observer, if any, of an accepted step.
    fn notify(&mut self, iteration: usize, merit: f64, mu: f64, alpha: f64) {
        if let Some(cb) = self.on_iteration.as_mut() {
            cb(&Progress {
                iteration: self.iterations_before + iteration,
                merit,
                mu,
                alpha,
            });
        }
    }

    /// The current gains (valid after [`Ilqg::solve`]).
    pub fn gains(&self) -> &[DMatrix<f64>] {
        &self.gains
    }

    /// The value Hessians `S_{k+1}` that the last stochastic backward pass left for each knot
    /// `k` (the line search's merit reads them; a deterministic pass leaves them as they were).
    /// Only their rows and columns where the noise can act are kept: all of them unless the
    /// model declares those rows ([`StateSupport::c`]: the delayed plant's are the plant's),
    /// and the entries outside are stale.
    pub fn value_hessians(&self) -> &[DMatrix<f64>] {
        &self.value_hessians
    }

    /// The dynamics linearised at every knot of the last solution's nominal (valid after a
    /// solve: the nominal is linearised after every accepted step).
    pub(crate) fn linearizations(&self) -> &[Linearization] {
        &self.nominal.lin
    }

    /// The gains of one backward pass at the last solution's nominal without regularisation
    /// (μ = 0) and without the noise terms: the LQR gains of the problem linearised there, which
    /// the last pass of a solve (at the μ then in force) only approximates. Replaces the
    /// workspace's gains, which a later [`Ilqg::resolve_shifted`] rolls out with. `None` before
    /// any solve, or when some `Q_uu` is not positive definite without regularisation.
    pub(crate) fn unregularized_gains(&mut self, problem: &Problem) -> Option<&[DMatrix<f64>]> {
        if !self.solved || self.check_size(problem).is_err() {
            return None;
        }
        if self.backward_pass(problem, 0.0, false).is_some() {
            return Some(&self.gains);
        }
        // Put back the gains of the solve's own last pass, for the warm starts that use them.
        let (mu, stochastic) = self.last_pass;
        self.backward_pass(problem, mu, stochastic);
        None
    }
}

/// `dst = src`, in place when every matrix has its shape already (no allocation).
fn copy_knots<R: Dim, C: Dim>(dst: &mut Vec<OMatrix<f64, R, C>>, src: &[OMatrix<f64, R, C>])
where
    DefaultAllocator: Allocator<R, C>,
{
    if dst.len() == src.len() && dst.iter().zip(src).all(|(d, s)| d.shape() == s.shape()) {
        for (d, s) in dst.iter_mut().zip(src) {
            d.copy_from(s);
        }
    } else {
        *dst = src.to_vec();
    }
}
