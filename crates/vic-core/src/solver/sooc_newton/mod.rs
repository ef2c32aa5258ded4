//! Stagewise Newton for stochastic optimal open-loop control: the open-loop expected cost
//! `J(u) = Σ_k ℓ(m_k, u_k) + ½ tr(ℓ_xx P_k) + g(m_N) + ½ tr(g_xx P_N)` of the moment dynamics
//! `z = (m, vech P)` ([`MomentDynamics`], after Berret & Jean 2020) minimised over the box-limited
//! controls.
//!
//! Why not the ILQG/iLQR machinery: a Gauss–Newton model of `z⁺ = F(z, u)` keeps `Fᵀ V F` and
//! drops `λ · F_zz`. The expected cost is linear in `P`, and `P⁺ = A P Aᵀ + …` is where the
//! stiffness acts (through `A`), so the dropped term holds the curvature that makes stiffness worth
//! buying; without it the model is badly conditioned (eigenvalues from 1e-6 to 4e4) and the solver
//! crawls with large regularisation. Here the backward pass adds the costate-weighted second
//! derivatives ([`MomentExpansion::curvature`]): with the costates `λ` of the current trajectory
//! this is Pantoja's stagewise Newton (Pantoja 1988; Dunn & Bertsekas 1989), the exact Newton step
//! of `J` over the whole control sequence computed stage by stage in `O(N)`, up to the third
//! derivatives of the flow that the curvature leaves out. Box limits are handled per stage as in
//! control-limited DDP (Tassa, Mansard & Todorov 2014): the stage QP is solved by projected Newton,
//! clamped controls get no feedback. The step is applied with its feedback on `δz` and a
//! backtracking line search on the true `J`; Levenberg–Marquardt regularisation (relative to each
//! control's Gauss–Newton curvature `ℓ_uu + Bᵀ V B`, which makes it independent of units and of
//! how cheap the control is in the cost) guards indefinite models.
//!
//! Convergence ([`Optimality`]) is judged on the exact gradient from the adjoint, not on the
//! model: the scaled projected gradient (each control's scale capped by its own exact curvature,
//! the diagonal of `∇²J`, from a pass beside the backward one when it decides the test) and the
//! Newton model's predicted decrease, both relative to `J`.

use super::Bounds;
use super::boxqp::MAX_QP;
use super::sooc::{MomentCost, MomentDynamics, MomentExpansion};
use crate::cost::CostDerivatives;
use crate::dense::zero;
use crate::dynamics::Dynamics;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use std::time::{Duration, Instant};

mod backward;
mod expand;
mod forward;
mod optimality;
mod options;
mod resolve;
mod state;

pub use backward::Indefinite;
use backward::{Backstep, Backward, Curvature};
use forward::rollout;
pub use optimality::Optimality;
use optimality::control_scales;
pub use options::{SoocOptions, SoocStop};
use state::{Damping, ModelState, Phase, Tally};

/// Relative regularisation above which an iteration gives up on the Newton model and takes a
/// Gauss–Newton step instead.
const NEWTON_MU_LIMIT: f64 = 1e6;

/// While the Newton model fails, it is tried again every this many iterations.
const NEWTON_RETRY: usize = 4;

/// Relative predicted decrease at the level of floating-point round-off of `J`.
const ROUND_OFF: f64 = 1e-13;

/// Kept third derivatives ([`SoocOptions::keep_third_derivatives`]) only after an exact step
/// that predicted more than this many times the decrease tolerance: after a smaller one the
/// next point is likely the optimum, and only an exact model there can say so.
const KEEP_FACTOR: f64 = 1e3;

/// A solution of the open-loop moment problem.
#[derive(Debug, Clone)]
pub struct SoocSolution {
    /// Controls `u_0 .. u_{N−1}`.
    pub u: Vec<DVector<f64>>,
    /// Moment states `z_0 ..= z_N`, `z = (m, vech P)`.
    pub z: Vec<DVector<f64>>,
    /// The open-loop expected cost `J`.
    pub expected_cost: f64,
    /// Number of accepted Newton steps.
    pub iterations: usize,
    pub stop: SoocStop,
    /// The optimality measures at the returned controls.
    pub optimality: Optimality,
    pub solve_time: Duration,
    /// `J` after each accepted step.
    pub history: Vec<f64>,
    /// Stage `Q_uu` convexified over the solve, summed over the backward passes
    /// ([`Indefinite::SaddleFree`]; always 0 with [`Indefinite::Regularize`]).
    pub convexified: usize,
    /// Accepted steps taken while the model left the flow's third derivatives out
    /// ([`SoocOptions::third_derivatives_below`]; 0 by default).
    pub without_third: usize,
    /// Accepted steps taken with the previous point's third derivatives
    /// ([`SoocOptions::keep_third_derivatives`]; 0 by default).
    pub kept_third: usize,
    /// Knots whose flow third derivatives a re-solve over the remaining movement took from the
    /// previous solve, its start being that solve's end point there
    /// ([`SoocSolver::resolve_remaining`]; 0 otherwise).
    pub carried_third: usize,
}

/// Errors of a solve: the problem does not fit the workspace, or cannot be started.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SoocError {
    #[error(
        "problem size {got:?} (states, controls, horizon) differs from the workspace's {want:?}"
    )]
    SizeMismatch {
        got: (usize, usize, usize),
        want: (usize, usize, usize),
    },
    #[error("{what} has {got} entries, expected {want}")]
    Length {
        what: &'static str,
        got: usize,
        want: usize,
    },
    #[error("the initial controls make the mean or covariance non-finite")]
    NonFiniteStart,
    #[error("there is no previous solution to shift; solve once first")]
    NoPreviousSolution,
}

/// The open-loop moment problem: moment dynamics and cost over `horizon` steps from a plant state
/// `x0` known exactly (`P_0 = 0`) or known up to a covariance `P_0`, with control limits.
pub struct SoocProblem<'a> {
    pub dynamics: &'a MomentDynamics<'a>,
    pub cost: &'a MomentCost<'a>,
    /// Initial plant state: the mean (`n` values; the covariance starts at 0), or the whole
    /// moment state, the mean followed by `vech(P_0)` (`n + n(n+1)/2` values).
    pub x0: &'a [f64],
    pub bounds: &'a Bounds,
    pub horizon: usize,
}

/// A callback for accepted steps; it receives the same report as ILQG's progress.
pub type Observer = std::sync::Arc<dyn Fn(&crate::solver::ilqg::Progress) + Send + Sync>;

/// The solver with its preallocated workspace, sized for one problem size; reuse it across solves
/// (the receding-horizon replanning of [`SoocSolver::resolve_shifted`], the shrinking horizon of
/// [`SoocSolver::resolve_remaining`] and of a [`SoocSolver::solve`] over fewer knots). A solve
/// allocates its solution; its iterations allocate nothing (test `sooc_workspace`).
pub struct SoocSolver {
    pub options: SoocOptions,
    /// Told of every accepted step (iteration, `J`, relative μ, step length): progress for
    /// long solves. Not called otherwise, so it costs nothing when unset.
    pub observer: Option<Observer>,
    n: usize,
    nu: usize,
    horizon: usize,
    z: Vec<DVector<f64>>,
    u: Vec<DVector<f64>>,
    cand_z: Vec<DVector<f64>>,
    cand_u: Vec<DVector<f64>>,
    expansions: Vec<MomentExpansion>,
    /// The Newton model's curvature per knot, with the second-order expansions.
    curvatures: Vec<Curvature>,
    derivs: Vec<CostDerivatives>,
    lam: Vec<DVector<f64>>,
    grad: Vec<DVector<f64>>,
    ff: Vec<DVector<f64>>,
    gains: Vec<DMatrix<f64>>,
    /// The diagonal of the exact `∇²J` (each control moved alone), when the convergence test
    /// last needed it: the curvature cap of the criterion's scales.
    hess_diag: Vec<DVector<f64>>,
    /// The expansions hold the Newton model at the current controls.
    newton_model: bool,
    bw: Backward,
    dz: DVector<f64>,
    /// Whether `u` holds a solution that [`SoocSolver::resolve_shifted`] may shift.
    solved: bool,
}

impl SoocSolver {
    /// A workspace for the moment dynamics' sizes (and noise kind) over `horizon` steps.
    pub fn new(dynamics: &MomentDynamics, horizon: usize, options: SoocOptions) -> Self {
        let (n, m) = (dynamics.n(), dynamics.nu());
        assert!(m <= MAX_QP, "at most {MAX_QP} controls");
        let nz = n + super::sooc::vech_len(n);
        SoocSolver {
            options,
            observer: None,
            n,
            nu: m,
            horizon,
            z: (0..=horizon).map(|_| DVector::zeros(nz)).collect(),
            u: (0..horizon).map(|_| DVector::zeros(m)).collect(),
            cand_z: (0..=horizon).map(|_| DVector::zeros(nz)).collect(),
            cand_u: (0..horizon).map(|_| DVector::zeros(m)).collect(),
            expansions: (0..horizon)
                .map(|_| MomentExpansion::for_dynamics(dynamics))
                .collect(),
            curvatures: (0..horizon).map(|_| Curvature::new(nz, m)).collect(),
            derivs: (0..=horizon).map(|_| CostDerivatives::new(nz, m)).collect(),
            lam: (0..=horizon).map(|_| DVector::zeros(nz)).collect(),
            grad: (0..horizon).map(|_| DVector::zeros(m)).collect(),
            ff: (0..horizon).map(|_| DVector::zeros(m)).collect(),
            gains: (0..horizon).map(|_| DMatrix::zeros(m, nz)).collect(),
            hess_diag: (0..horizon).map(|_| DVector::zeros(m)).collect(),
            newton_model: false,
            bw: Backward::new(nz, m),
            dz: DVector::zeros(nz),
            solved: false,
        }
    }

    /// The number of knots the workspace holds now.
    pub fn horizon(&self) -> usize {
        self.horizon
    }

    /// A workspace sized for `problem`.
    pub fn for_problem(problem: &SoocProblem, options: SoocOptions) -> Self {
        Self::new(problem.dynamics, problem.horizon, options)
    }

    pub(super) fn check(&self, problem: &SoocProblem) -> Result<(), SoocError> {
        self.check_for(problem, self.horizon)
    }

    /// [`SoocSolver::check`] for a workspace of `horizon` knots (the sizes the call will fit it
    /// to), before it changes.
    pub(super) fn check_for(&self, problem: &SoocProblem, horizon: usize) -> Result<(), SoocError> {
        let got = (problem.dynamics.n(), problem.dynamics.nu(), problem.horizon);
        let want = (self.n, self.nu, horizon);
        if got != want {
            return Err(SoocError::SizeMismatch { got, want });
        }
        if problem.x0.len() != self.n && problem.x0.len() != self.z[0].len() {
            return Err(SoocError::Length {
                what: "x0",
                got: problem.x0.len(),
                want: self.n,
            });
        }
        Ok(())
    }

    /// Solves from the control sequence `u_init` (clamped into the limits). The workspace fits
    /// itself to the problem's horizon: a shorter one drops knots (nothing is allocated; the
    /// central controller's re-solves over a shrinking rest of the movement), a longer one takes
    /// a new workspace. Either way the result is that of a new workspace, to the bit.
    pub fn solve(
        &mut self,
        problem: &SoocProblem,
        u_init: &[DVector<f64>],
    ) -> Result<SoocSolution, SoocError> {
        // Every check before the workspace changes: a refused call leaves it as it was.
        if u_init.len() != problem.horizon {
            return Err(SoocError::Length {
                what: "u_init",
                got: u_init.len(),
                want: problem.horizon,
            });
        }
        if let Some(src) = u_init.iter().find(|u| u.len() != self.nu) {
            return Err(SoocError::Length {
                what: "a control of u_init",
                got: src.len(),
                want: self.nu,
            });
        }
        self.check_for(problem, problem.horizon)?;
        self.fit(problem);
        for (dst, src) in self.u.iter_mut().zip(u_init) {
            dst.copy_from(src);
        }
        self.run(problem, false)
    }

    /// The solver proper, from the controls in `self.u`: per iteration the model (first
    /// derivatives, costates, and the Newton curvature when tried), the convergence test on the
    /// exact gradient, the regularised backward pass and the line search on the true `J`. With
    /// `carry`, the first expansion keeps the flow derivatives the workspace holds for the very
    /// points it meets ([`SoocSolver::resolve_remaining`]).
    pub(super) fn run(
        &mut self,
        problem: &SoocProblem,
        carry: bool,
    ) -> Result<SoocSolution, SoocError> {
        let start = Instant::now();
        self.solved = false;
        let mut cost = self.start(problem)?;
        let scale = control_scales(problem.bounds);
        let mut damping = Damping { mu: 0.0, step: 1.0 };
        let mut model = ModelState {
            needs_expansion: true,
            has_second_order: false,
            gauss_newton_run: 0,
            third: self.options.flow_third_derivatives
                && self.options.third_derivatives_below == f64::INFINITY,
            kept: false,
            fresh: false,
            first: true,
            last_predicted: f64::INFINITY,
            carry,
            carried: 0,
        };
        // Sized once: the iterations themselves allocate nothing.
        let mut tally = Tally {
            history: Vec::with_capacity(self.options.max_iterations),
            ..Tally::default()
        };
        let (stop, optimality) = loop {
            // The Newton model costs the flow's third derivatives. While it keeps failing (far
            // from the optimum), try it only every few iterations and take Gauss–Newton steps
            // in between.
            let try_newton = self.prepare_model(problem, &mut model, (&scale, cost));
            let (step, newton) =
                self.regularized_backward(problem.bounds, &mut damping, try_newton);
            self.newton_model = newton;
            // Only the Newton model itself (no stage convexified) predicts what a Newton step
            // gains; the Gauss–Newton model's prediction says nothing about optimality.
            let full = (model.third && !model.kept) || !self.options.flow_third_derivatives;
            let exact = step.filter(|s| newton && s.convexified == 0 && full);
            let pg = self.projected_gradient_tested(
                problem.bounds,
                &scale,
                cost,
                exact.is_some(),
                exact.map(|s| (s.dv1, s.dv2)),
            );
            if newton {
                model.gauss_newton_run = 0;
            } else {
                model.gauss_newton_run += 1;
            }
            tally.convexified += step.map_or(0, |s| s.convexified);
            let Some(Backstep { dv1, dv2, .. }) = step else {
                break (
                    SoocStop::RegularizationLimit,
                    self.optimality(pg, None, cost),
                );
            };
            let optimality = self.optimality(pg, exact.map(|s| s.dv1 + s.dv2), cost);
            if optimality.met() {
                break (SoocStop::Converged, optimality);
            }
            if tally.iterations >= self.options.max_iterations {
                break (SoocStop::MaxIterations, optimality);
            }
            let phase = Phase {
                full,
                kept: model.kept,
                predicted: (dv1, dv2),
                predicted_decrease: optimality.predicted_decrease,
            };
            let moved = (&mut damping, &mut model, &mut tally);
            if let Some(stop) = self.advance(problem, &mut cost, phase, moved) {
                break (stop, optimality);
            }
        };
        self.solved = true;
        Ok(SoocSolution {
            u: self.u.clone(),
            z: self.z.clone(),
            expected_cost: cost,
            iterations: tally.iterations,
            stop,
            optimality,
            solve_time: start.elapsed(),
            history: tally.history,
            convexified: tally.convexified,
            without_third: tally.without_third,
            kept_third: tally.kept_third,
            carried_third: model.carried,
        })
    }

    /// The line search of one iteration: on success the candidate becomes the iterate (`cost`
    /// its cost) and a full step lowers μ; on failure μ grows, or the exact model replaces the
    /// Gauss–Newton one from a fresh μ. `Some` when the solve must stop.
    fn advance(
        &mut self,
        problem: &SoocProblem,
        cost: &mut f64,
        phase: Phase,
        (damping, model, tally): (&mut Damping, &mut ModelState, &mut Tally),
    ) -> Option<SoocStop> {
        let (dv1, dv2) = phase.predicted;
        match self.line_search(problem, *cost, dv1, dv2) {
            Some((c, alpha)) => {
                std::mem::swap(&mut self.z, &mut self.cand_z);
                std::mem::swap(&mut self.u, &mut self.cand_u);
                // Close enough to the optimum for the exact Hessian (for good).
                let gain = (*cost - c) / c.abs().max(1e-300);
                if self.options.flow_third_derivatives
                    && gain < self.options.third_derivatives_below
                {
                    model.third = true;
                }
                *cost = c;
                model.last_predicted = phase.predicted_decrease;
                tally.iterations += 1;
                tally.without_third += usize::from(!phase.full && !phase.kept);
                tally.kept_third += usize::from(phase.kept);
                tally.history.push(c);
                self.notify(tally.iterations, c, damping.mu, alpha);
                model.needs_expansion = true;
                // A full step: trust the model more.
                if alpha >= 0.5 {
                    damping.decrease(&self.options);
                }
                None
            }
            // Nothing left to gain above round-off, yet the gradient test fails: stop rather
            // than inflate μ.
            None if phase.predicted_decrease < ROUND_OFF || !damping.increase(&self.options) => {
                if phase.full {
                    return Some(SoocStop::RegularizationLimit);
                }
                // The model without the third derivatives, or with those of the previous point,
                // found no descent at any μ: the exact one, from a fresh μ.
                if model.kept {
                    model.kept = false;
                    for e in &mut self.expansions {
                        e.forget_third();
                    }
                }
                model.third = true;
                model.has_second_order = false;
                *damping = Damping { mu: 0.0, step: 1.0 };
                None
            }
            None => None,
        }
    }

    /// The diagonal of the exact `∇²J` (`∂²J/∂u_{k,j}²`, each control moved alone) at the
    /// returned controls, what the criterion caps the scales with; `None` unless the last
    /// iteration had the Newton model there (it has whenever the solve converged).
    pub fn hessian_diagonal(&mut self) -> Option<&[DVector<f64>]> {
        if !self.newton_model {
            return None;
        }
        self.hessian_diagonal_pass();
        Some(&self.hess_diag)
    }

    /// Tells the observer, if any, of an accepted step.
    fn notify(&self, iteration: usize, merit: f64, mu: f64, alpha: f64) {
        if let Some(observe) = &self.observer {
            observe(&crate::solver::ilqg::Progress {
                iteration,
                merit,
                mu,
                alpha,
            });
        }
    }

    /// Clamps the controls, clears the gains and rolls the start out: its cost.
    fn start(&mut self, problem: &SoocProblem) -> Result<f64, SoocError> {
        for u in &mut self.u {
            problem.bounds.clamp(u.as_mut_slice());
        }
        for g in &mut self.gains {
            zero(g);
        }
        // The stage QPs start from 0 as in a new workspace (a previous solve's last steps
        // would be starts of their own, rounding the result differently).
        for f in &mut self.ff {
            zero(f);
        }
        zero(&mut self.z[0]);
        self.z[0]
            .rows_mut(0, problem.x0.len())
            .copy_from_slice(problem.x0);
        let cost = rollout(problem, &mut self.z, &self.u);
        if cost.is_finite() {
            Ok(cost)
        } else {
            Err(SoocError::NonFiniteStart)
        }
    }

    /// Brings the model up to date with the trajectory: first derivatives and costates after
    /// a step, the Newton curvature when this iteration tries Newton. Whether it does.
    fn prepare_model(
        &mut self,
        problem: &SoocProblem,
        model: &mut ModelState,
        (scale, cost): (&[f64], f64),
    ) -> bool {
        let try_newton = model.gauss_newton_run.is_multiple_of(NEWTON_RETRY);
        if model.needs_expansion {
            // The exact Newton model comes next: its third-order flows give the first
            // expansion's second derivatives as well.
            let third = try_newton && model.third;
            // Keep the previous point's third derivatives when that point took them anew.
            model.kept = third
                && self.options.keep_third_derivatives
                && model.fresh
                && model.last_predicted > KEEP_FACTOR * self.options.decrease_tolerance;
            if model.kept {
                self.expand_keeping_third(problem);
            } else if std::mem::take(&mut model.carry) {
                model.carried = self.expand_reusing_third(problem, third);
            } else {
                self.expand(problem, third);
            }
            model.fresh = third && !model.kept;
            self.costates();
            model.needs_expansion = false;
            model.has_second_order = false;
            if std::mem::take(&mut model.first)
                && !model.third
                && self.near_optimum(problem, scale, cost)
            {
                // A warm start at (nearly) an optimum: the exact model from the first step,
                // where the Gauss–Newton one is worst (its third derivatives anew, by their
                // own flows, in the second-order pass).
                model.third = true;
                model.fresh = true;
            }
        }
        if try_newton && !model.has_second_order {
            self.expand_second_order(problem, model.third);
            model.has_second_order = true;
        }
        try_newton
    }

    /// The optimality measures for the projected gradient `pg` (already relative) and the
    /// Newton model's predicted change `dv` (`None`: no Newton prediction).
    fn optimality(&self, pg: f64, dv: Option<f64>, cost: f64) -> Optimality {
        Optimality {
            projected_gradient: pg,
            predicted_decrease: dv.map_or(f64::INFINITY, |dv| -dv / cost.abs().max(1e-300)),
            gradient_tolerance: self.options.gradient_tolerance,
            decrease_tolerance: self.options.decrease_tolerance,
        }
    }

    /// Backward passes, raising μ until every stage QP is convex. Far from the optimum the
    /// Newton model can be too indefinite for any sensible μ; then this iteration uses the
    /// Gauss–Newton model (no curvature term, the ILQG model), which is convex in the controls,
    /// and a later iteration tries Newton again. With [`Indefinite::SaddleFree`] a Newton pass
    /// convexifies the indefinite stages instead. The backward pass's prediction (`None`: μ
    /// passed its limit) and whether it is from the Newton model.
    fn regularized_backward(
        &mut self,
        bounds: &Bounds,
        damping: &mut Damping,
        try_newton: bool,
    ) -> (Option<Backstep>, bool) {
        let mut newton = try_newton;
        let mut mu_here = damping.mu;
        let saddle_free = self.options.indefinite == Indefinite::SaddleFree;
        let predicted = loop {
            if let Some(dv) = self.backward(bounds, mu_here, newton, newton && saddle_free) {
                break Some(dv);
            }
            damping.step = (damping.step * 2.0).max(2.0);
            mu_here = (mu_here * damping.step).max(self.options.mu_min);
            if newton && mu_here > NEWTON_MU_LIMIT {
                newton = false;
                mu_here = damping.mu;
            } else if mu_here > self.options.mu_max {
                break None;
            }
        };
        if newton {
            damping.mu = mu_here;
        }
        (predicted, newton)
    }

    /// The second-order pieces of the moment step at every knot and their contraction with the
    /// costates, the curvature `H` (in parallel: the knots are independent), for the Newton
    /// model. Computed here once, not in each backward pass, which runs one knot after another
    /// and again at every higher μ.
    fn expand_second_order(&mut self, problem: &SoocProblem, third: bool) {
        let (z, u, lam) = (&self.z, &self.u, &self.lam);
        self.expansions
            .par_iter_mut()
            .zip(self.curvatures.par_iter_mut())
            .enumerate()
            .for_each(|(k, (e, c))| {
                let (zk, uk) = (z[k].as_slice(), u[k].as_slice());
                let lam_next = lam[k + 1].as_slice();
                problem.dynamics.second_order(k, zk, uk, lam_next, third, e);
                e.curvature(lam_next, &mut c.hzz, &mut c.huz, &mut c.huu);
            });
    }

    /// The costates `λ_N = ∇g`, `λ_k = ℓ_z + Aᵀ λ_{k+1}`, and the exact gradient
    /// `∇_{u_k} J = ℓ_u + Bᵀ λ_{k+1}`.
    fn costates(&mut self) {
        let h = self.horizon;
        self.lam[h].copy_from(&self.derivs[h].lx);
        for k in (0..h).rev() {
            let (head, tail) = self.lam.split_at_mut(k + 1);
            let next = &tail[0];
            let e = &self.expansions[k];
            head[k].copy_from(&self.derivs[k].lx);
            head[k].gemv_tr(1.0, &e.a, next, 1.0);
            self.grad[k].copy_from(&self.derivs[k].lu);
            self.grad[k].gemv_tr(1.0, &e.b, next, 1.0);
        }
    }
}
