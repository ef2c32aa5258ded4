//! Iterative LQG for stochastic plants with state- and control-dependent noise (Todorov & Li 2005,
//! DESIGN §4), with box-constrained controls by projected Newton (Tassa, Mansard & Todorov 2014),
//! adaptive Levenberg–Marquardt regularisation and a backtracking line search.
//!
//! The line search compares *expected* costs when the plant is stochastic: the nominal cost plus
//! the second-order noise cost of the candidate under the new feedback gains
//! ([`crate::core::solver::moments::expected_cost`]). The deterministic cost alone would reject the very steps the noise
//! terms of the backward pass ask for.

use super::boxqp::{MAX_QP, QpStatus, solve_box_qp};
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

/// The ILQG solver with its preallocated workspace; reuse it for problems of the same size.
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
            bw: Backward {
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
            },
            value_hessians: (0..h).map(|_| DMatrix::zeros(nx, nx)).collect(),
            noise_scratch: DMatrix::zeros(nx, nw),
            dims: (nx, nu, nw, h),
        }
    }

    /// Solves from the initial control sequence `u_init` (warm start; clamped into the limits).
    pub fn solve(&mut self, problem: &Problem, u_init: &[DVector<f64>]) -> Solution {
        let start = Instant::now();
        let (nx, nu, nw, horizon) = self.dims;
        assert_eq!(
            (
                problem.dynamics.nx(),
                problem.dynamics.nu(),
                problem.dynamics.nw(),
                problem.horizon
            ),
            (nx, nu, nw, horizon),
            "problem size changed since Ilqg::new"
        );
        assert_eq!(
            u_init.len(),
            horizon,
            "u_init must have one control per step"
        );
        let stochastic = self.options.stochastic && nw > 0;

        // Initial nominal: open-loop rollout of u_init.
        for g in &mut self.gains {
            g.fill(0.0);
        }
        for k in 0..horizon {
            self.ff[k].fill(0.0);
            self.nominal.u[k].copy_from(&u_init[k]);
            problem.bounds.clamp(self.nominal.u[k].as_mut_slice());
        }
        self.nominal.x[0].copy_from_slice(&problem.x0);
        let mut ok = rollout(problem, &mut self.nominal, None, None, 0.0);
        assert!(
            ok,
            "the initial control sequence makes the plant diverge (non-finite state)"
        );
        linearize(problem, &mut self.nominal);

        let mut mu = self.options.mu_init;
        let mut mu_step = 1.0_f64;
        let mut iterations = 0;
        let mut history = Vec::new();
        let mut expected = self.nominal.cost;
        let mut stop = StopReason::MaxIterations;
        let mut finish_after_backward = false;

        for _ in 0..self.options.max_iterations {
            // Backward pass, raising μ until every Q_uu is positive definite.
            let (dv1, dv2) = loop {
                match self.backward(problem, mu, stochastic) {
                    Some((s0, dv)) => {
                        expected = s0;
                        break dv;
                    }
                    None => {
                        mu_step = (mu_step * 2.0).max(2.0);
                        mu = (mu * mu_step).max(self.options.mu_min);
                        if mu > self.options.mu_max {
                            stop = StopReason::RegularizationLimit;
                            break (0.0, 0.0);
                        }
                    }
                }
            };
            if stop == StopReason::RegularizationLimit {
                break;
            }
            if finish_after_backward {
                stop = StopReason::SmallImprovement;
                break;
            }
            let grad = self
                .ff
                .iter()
                .zip(&self.nominal.u)
                .flat_map(|(l, u)| {
                    l.iter()
                        .zip(u.iter())
                        .map(|(l, u)| l.abs() / (u.abs() + 1.0))
                })
                .fold(0.0, f64::max);
            if grad < self.options.gradient_tolerance {
                stop = StopReason::SmallGradient;
                break;
            }

            // The merit of the current nominal under the new gains, for a like-for-like comparison.
            let merit_now = self.merit(problem, stochastic, false);
            // Nothing left to gain at first order: the predicted improvement of an (almost)
            // undamped Newton step is negligible.
            let trusted_mu = TRUSTED_MU * self.value_scale();
            if mu <= trusted_mu && -(dv1 + dv2) < self.options.tolerance * merit_now.abs() {
                stop = StopReason::SmallImprovement;
                break;
            }

            let mut accepted = None;
            for alpha in [
                1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125, 0.015625, 0.0078125, 0.001,
            ] {
                self.candidate.x[0].copy_from_slice(&problem.x0);
                ok = rollout(
                    problem,
                    &mut self.candidate,
                    Some((&self.nominal, &self.ff, &self.gains)),
                    Some(&problem.bounds),
                    alpha,
                );
                if !ok {
                    continue;
                }
                let merit_new = self.merit(problem, stochastic, true);
                let predicted = -alpha * (dv1 + alpha * dv2);
                let actual = merit_now - merit_new;
                let ratio = if predicted > 0.0 {
                    actual / predicted
                } else {
                    actual.signum()
                };
                if actual > 0.0 && ratio > 1e-4 {
                    accepted = Some((merit_now, merit_new, alpha));
                    break;
                }
            }

            match accepted {
                Some((before, after, alpha)) => {
                    std::mem::swap(&mut self.nominal, &mut self.candidate);
                    linearize(problem, &mut self.nominal);
                    iterations += 1;
                    history.push(after);
                    if let Some(cb) = self.on_iteration.as_mut() {
                        cb(&Progress {
                            iteration: iterations,
                            merit: after,
                            mu,
                            alpha,
                        });
                    }
                    if alpha >= self.options.shrink_below_step || !self.options.damp_short_steps {
                        // The local model was trusted: lower μ (Tassa's schedule).
                        mu_step = (mu_step / 2.0).min(0.5);
                        mu = if mu * mu_step > self.options.mu_min {
                            mu * mu_step
                        } else {
                            0.0
                        };
                    } else {
                        // Only a short step helped: the quadratic model overshoots (typically in
                        // the stiffness, whose effect is bilinear). Damp the next Newton step.
                        mu_step = (mu_step * 2.0).max(2.0);
                        mu = (mu * mu_step).max(self.options.mu_min);
                    }
                    // A small improvement means convergence only after a long step with little
                    // regularisation; a short, heavily damped step improves little anywhere.
                    let trusted = alpha >= self.options.shrink_below_step && mu <= trusted_mu;
                    if trusted
                        && (before - after) / after.abs().max(1e-300) < self.options.tolerance
                    {
                        // One more backward pass so that the gains and s_0 belong to this nominal.
                        finish_after_backward = true;
                    }
                }
                None => {
                    mu_step = (mu_step * 2.0).max(2.0);
                    mu = (mu * mu_step).max(self.options.mu_min);
                    if mu > self.options.mu_max {
                        stop = StopReason::RegularizationLimit;
                        break;
                    }
                }
            }
        }

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

    /// One backward pass at the nominal with regularisation `mu`. Returns the predicted expected
    /// cost `s_0` and the expected-improvement terms `(Σ lᵀ Q_u, Σ ½ lᵀ Q_uu l)`, or `None` when a
    /// `Q_uu` is not positive definite.
    fn backward(
        &mut self,
        problem: &Problem,
        mu: f64,
        stochastic: bool,
    ) -> Option<(f64, (f64, f64))> {
        let (_, nu, _, horizon) = self.dims;
        let bw = &mut self.bw;
        let traj = &self.nominal;
        let term = &traj.derivs[horizon];
        copy(&term.lxx, &mut bw.s_mat);
        bw.s_vec.copy_from(&term.lx);
        let mut s0 = problem.cost.terminal(traj.x[horizon].as_slice());
        let (mut dv1, mut dv2) = (0.0, 0.0);

        for k in (0..horizon).rev() {
            if stochastic {
                // Only the stochastic merit reads them.
                copy(&bw.s_mat, &mut self.value_hessians[k]);
            }
            let (lin, d) = (&traj.lin[k], &traj.derivs[k]);
            let mut q0 = problem
                .cost
                .running(k, traj.x[k].as_slice(), traj.u[k].as_slice())
                + s0;
            // The products take A, B, Cx, Cu by their nonzeros (see `sparse`): n·nnz, not n³.
            let sp = &traj.sparse[k];
            bw.qx.copy_from(&d.lx);
            sp.a.tr_mul_vec_add(1.0, bw.s_vec.as_slice(), bw.qx.as_mut_slice());
            bw.qu.copy_from(&d.lu);
            sp.b.tr_mul_vec_add(1.0, bw.s_vec.as_slice(), bw.qu.as_mut_slice());
            sp.a.right_mul(&bw.s_mat, &mut bw.sa);
            sp.b.right_mul(&bw.s_mat, &mut bw.sb);
            copy(&d.lxx, &mut bw.qxx);
            transpose(&bw.sa, &mut bw.sat);
            sp.a.right_mul_add(&bw.sat, &mut bw.qxx);
            copy(&d.luu, &mut bw.quu);
            sp.b.tr_mul_add(1.0, &bw.sb, &mut bw.quu);
            copy(&d.lux, &mut bw.qux);
            sp.b.tr_mul_add(1.0, &bw.sa, &mut bw.qux);
            if stochastic && lin.noise != NoiseKind::None {
                for i in 0..lin.c.ncols() {
                    bw.sc.gemv(1.0, &bw.s_mat, &lin.c.column(i), 0.0);
                    q0 += 0.5 * lin.c.column(i).dot(&bw.sc);
                    if lin.noise == NoiseKind::Dependent {
                        let (cx, cu) = (&sp.cx[i], &sp.cu[i]);
                        cx.tr_mul_vec_add(1.0, bw.sc.as_slice(), bw.qx.as_mut_slice());
                        cu.tr_mul_vec_add(1.0, bw.sc.as_slice(), bw.qu.as_mut_slice());
                        cx.right_mul(&bw.s_mat, &mut bw.scx);
                        cu.right_mul(&bw.s_mat, &mut bw.scu);
                        transpose(&bw.scx, &mut bw.sat);
                        cx.right_mul_add(&bw.sat, &mut bw.qxx);
                        cu.tr_mul_add(1.0, &bw.scu, &mut bw.quu);
                        cu.tr_mul_add(1.0, &bw.scx, &mut bw.qux);
                    }
                }
            }

            // Regularisation on the value function (Tassa, Erez & Todorov 2012): S + μ I in the
            // control terms. As μ grows the gains tend to −(BᵀB)⁻¹BᵀA, which cancels state
            // deviations, rather than to zero (open loop), so the line search stays meaningful in
            // an unstable field. The value update below uses the unregularised Q.
            copy(&bw.quu, &mut bw.quu_reg);
            copy(&bw.qux, &mut bw.qux_reg);
            if mu > 0.0 {
                sp.b.tr_mul_add(mu, &lin.b, &mut bw.quu_reg);
                sp.b.tr_mul_add(mu, &lin.a, &mut bw.qux_reg);
                for j in 0..nu {
                    // A trace of control-space damping for controls that do not move the state.
                    bw.quu_reg[(j, j)] += mu * 1e-6;
                }
            }

            // Feedforward step and gains from the box QP on the regularised Q_uu.
            let u = &traj.u[k];
            let mut lower = [0.0; MAX_QP];
            let mut upper = [0.0; MAX_QP];
            for j in 0..nu {
                lower[j] = problem.bounds.lower[j] - u[j];
                upper[j] = problem.bounds.upper[j] - u[j];
            }
            let quu = &bw.quu_reg;
            let h = |i: usize, j: usize| quu[(i, j)];
            let qp = solve_box_qp(
                h,
                bw.qu.as_slice(),
                &lower[..nu],
                &upper[..nu],
                self.ff[k].as_slice(),
            );
            if qp.status == QpStatus::NotPositiveDefinite {
                return None;
            }
            let l = &mut self.ff[k];
            for j in 0..nu {
                l[j] = qp.x[j];
            }
            let gain = &mut self.gains[k];
            gain.as_mut_slice().fill(0.0);
            if let Some(regularized) = &qp.factor {
                let mut free = [0usize; MAX_QP];
                let mut nfree = 0;
                for j in (0..nu).filter(|&j| qp.free[j]) {
                    free[nfree] = j;
                    nfree += 1;
                }
                let free = &free[..nfree];
                let factor = regularized;
                let mut col = [0.0; MAX_QP];
                for c in 0..gain.ncols() {
                    for (a, &j) in free.iter().enumerate() {
                        col[a] = bw.qux_reg[(j, c)];
                    }
                    factor.solve(&mut col[..nfree]);
                    for (a, &j) in free.iter().enumerate() {
                        gain[(j, c)] = -col[a];
                    }
                }
            }

            // Value function update (Tassa 2012 form, valid with regularisation and clamping).
            bw.t_m.gemv(1.0, &bw.quu, l, 0.0); // Q_uu l
            let lqu = l.dot(&bw.qu);
            let lquul = l.dot(&bw.t_m);
            s0 = q0 + lqu + 0.5 * lquul;
            dv1 += lqu;
            dv2 += 0.5 * lquul;
            bw.t_m += &bw.qu; // Q_uu l + Q_u
            bw.s_vec.copy_from(&bw.qx);
            bw.s_vec.gemv_tr(1.0, gain, &bw.t_m, 1.0);
            bw.s_vec.gemv_tr(1.0, &bw.qux, l, 1.0);
            copy(&bw.qux, &mut bw.t_mn);
            bw.t_mn.gemm(1.0, &bw.quu, gain, 1.0); // Q_uu L + Q_ux
            // S = Q_xx + Lᵀ (Q_uu L + Q_ux) + Q_uxᵀ L as 2m rank-one updates, each an axpy on
            // contiguous columns of the transposed thin factors (nalgebra's transposed products
            // are plain dot loops).
            transpose(gain, &mut bw.lt);
            transpose(&bw.qux, &mut bw.xt);
            let n = bw.s_mat.nrows();
            let (gd, td) = (gain.as_slice(), bw.t_mn.as_slice());
            let (ltd, xtd) = (bw.lt.as_slice(), bw.xt.as_slice());
            let sd = bw.s_mat.as_mut_slice();
            sd.copy_from_slice(bw.qxx.as_slice());
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
        }
        Some((s0, (dv1, dv2)))
    }

    /// The current gains (valid after [`Ilqg::solve`]).
    pub fn gains(&self) -> &[DMatrix<f64>] {
        &self.gains
    }
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
/// `clamp(ū + α l + L (x − x̄))`; without, `traj.u` is used as it is. Returns false on divergence.
fn rollout(
    problem: &Problem,
    traj: &mut Trajectory,
    policy: Option<Policy>,
    bounds: Option<&Bounds>,
    alpha: f64,
) -> bool {
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
            return false;
        }
    }
    cost += problem.cost.terminal(traj.x[problem.horizon].as_slice());
    traj.cost = cost;
    cost.is_finite()
}

/// Linearises the dynamics and differentiates the cost along `traj`.
fn linearize(problem: &Problem, traj: &mut Trajectory) {
    use rayon::prelude::*;
    let h = problem.horizon;
    let (xs, us) = (&traj.x, &traj.u);
    // Knots are independent: linearise them in parallel. Each knot's result is computed the same
    // way whatever the thread count, so the solution does not depend on it.
    traj.lin[..h]
        .par_iter_mut()
        .zip(traj.sparse[..h].par_iter_mut())
        .zip(traj.derivs[..h].par_iter_mut())
        .enumerate()
        .with_min_len(8)
        .for_each(|(k, ((lin, sparse), d))| {
            let (x, u) = (xs[k].as_slice(), us[k].as_slice());
            problem.dynamics.linearize(k, x, u, lin);
            sparse.assign(lin);
            problem.cost.running_derivatives(k, x, u, d);
        });
    problem
        .cost
        .terminal_derivatives(xs[h].as_slice(), &mut traj.derivs[h]);
}
