//! Stochastic optimal open-loop control at O(n³) per knot: the same problem as
//! [`crate::solver::sooc_newton`] (the open-loop expected cost
//! `J(u) = Σ_k ℓ(m_k, u_k) + ½ tr(ℓ_xx P_k) + g(m_N) + ½ tr(g_xx P_N)` of the moment dynamics
//! `m⁺ = Φ(m, u)`, `P⁺ = A P Aᵀ + Σ_i (c_i c_iᵀ + Cx_i P Cx_iᵀ)`, after Berret & Jean 2020,
//! minimised over box-limited controls), with a model that never differentiates the covariance
//! propagation twice, in the spirit of zero-order robust optimisation (acados zoRO; Riccati-ZORO,
//! Messerer et al. 2025): the gradient is exact, the curvature is not.
//!
//! Per iteration, at the current controls:
//!
//! 1. roll the moments out (`m_k`, `P_k`, the true `J`);
//! 2. the covariance adjoint `Π_N = ½ g_xx`, `Π_k = ½ ℓ_xx + A_kᵀ Π_{k+1} A_k +
//!    Σ_i Cx_iᵀ Π_{k+1} Cx_i`: `tr(Π_k δP_k)` is the first-order change of the expected
//!    cost-to-go (`J` is linear in each `P_k`, `P⁺` linear in `P`);
//! 3. the surrogate stage cost `ℓ̃_k(m, u) = ℓ(m, u) + tr(Π_{k+1} (A P_k Aᵀ + W)(m, u))`, `P_k`
//!    and `Π_{k+1}` frozen: its first derivatives at the current point are the true ones
//!    (`Π_{k+1}` carries the effect of `P_{k+1}` on every later cost), so the mean's costates
//!    and `∇_u J` are exact. Its curvature keeps `2 tr(Π dA_a P dA_bᵀ)` (and the noise's like
//!    terms) over `v = (m, u)`: positive semidefinite, and the term through which stiffness (in
//!    `A`, linearly) buys a smaller covariance — what a Gauss–Newton model of the moment state
//!    `(m, vech P)` loses, because `J` is linear in `P` (DESIGN §5). With the mean's dynamics
//!    linearised this is an LQ problem whose condensed Hessian `M` (symmetric positive definite)
//!    a Riccati recursion inverts ([`precond`]);
//! 4. the step: projected Newton–CG ([`newton`]) on the exact Hessian of `J`, applied to a
//!    direction by differences of the exact gradient, preconditioned by `M⁻¹` (the surrogate
//!    misses the third derivatives of the flow, the mean's costate-weighted second derivatives
//!    and the coupling of one knot's `δP` with every later one: CG restores them), the controls
//!    held at a bound by their gradient fixed for the step (Bertsekas 1982); a backtracking line
//!    search on the true `J` along the projected step with the surrogate's feedback on the mean
//!    (optionally a trust region in the `M`-norm instead, [`SoocFastOptions::trust_region`]).
//!
//! Everything is n×n products (`O(n³)` per knot, plus the step's first derivatives), never the
//! `vech` Jacobian of the covariance step.
//!
//! Convergence ([`Optimality`]) is stated as for the Newton solver: the scaled projected gradient
//! of the exact `∇J`, relative to `J`, with each control's scale capped at `√(2|J| / h)`, and the
//! predicted decrease `−(gᵀd + ½ dᵀ H d)` of the Newton–CG step, relative to `J`. Here `h` is the
//! surrogate's curvature of the control (the diagonal of its stage `Q_uu`), and the quadratic
//! model's `H` is the exact Hessian on the Krylov space CG explored.

use super::Bounds;
use super::boxqp::MAX_QP;
use super::sooc::MomentDynamics;
use super::sooc_newton::{Optimality, SoocError, SoocProblem, SoocStop};
use crate::cost::CostDerivatives;
use crate::dense::zero;
use crate::dynamics::Dynamics;
use nalgebra::{DMatrix, DVector};
use std::time::{Duration, Instant};

mod forward;
mod model;
mod newton;
mod options;
mod precond;

use forward::rollout;
use model::Knot;
use newton::Cg;
pub use options::SoocFastOptions;
use precond::Precond;

/// A solution of the open-loop moment problem by [`SoocFastSolver`].
#[derive(Debug, Clone)]
pub struct SoocFastSolution {
    /// Controls `u_0 .. u_{N−1}`.
    pub u: Vec<DVector<f64>>,
    /// Moment states `z_0 ..= z_N`, `z = (m, vech P)`.
    pub z: Vec<DVector<f64>>,
    /// The open-loop expected cost `J`.
    pub expected_cost: f64,
    /// Number of accepted steps.
    pub iterations: usize,
    /// Conjugate-gradient iterations over all steps (each one Hessian-vector product, two
    /// gradients).
    pub cg_iterations: usize,
    pub stop: SoocStop,
    /// The optimality measures at the returned controls.
    pub optimality: Optimality,
    pub solve_time: Duration,
    /// `J` after each accepted step.
    pub history: Vec<f64>,
}

/// The solver with its workspace, sized for one problem size (made up front: an iteration
/// allocates nothing).
pub struct SoocFastSolver {
    pub options: SoocFastOptions,
    n: usize,
    nu: usize,
    horizon: usize,
    z: Vec<DVector<f64>>,
    u: Vec<DVector<f64>>,
    cand_z: Vec<DVector<f64>>,
    cand_u: Vec<DVector<f64>>,
    knots: Vec<Knot>,
    terminal: CostDerivatives,
    /// The covariance adjoint `Π_k` (n×n), `0 ..= N`.
    pi: Vec<DMatrix<f64>>,
    /// The mean's costates `λ_k`, `0 ..= N`.
    lam: Vec<DVector<f64>>,
    /// The exact `∇_{u_k} J`.
    grad: Vec<DVector<f64>>,
    /// Each control's curvature in the model (the stage `Q_uu` diagonal), the criterion's cap.
    curvature: Vec<DVector<f64>>,
    precond: Precond,
    /// The step's vectors; taken out of the solver while a step is computed.
    cg: Option<Cg>,
    tmp: DMatrix<f64>,
}

impl SoocFastSolver {
    /// A workspace for the moment dynamics' sizes over `horizon` steps.
    pub fn new(dynamics: &MomentDynamics, horizon: usize, options: SoocFastOptions) -> Self {
        let (n, m, p) = (dynamics.n(), dynamics.nu(), dynamics.base().nw());
        assert!(m <= MAX_QP, "at most {MAX_QP} controls");
        let nz = dynamics.nx();
        let vectors = |count: usize, len: usize| -> Vec<DVector<f64>> {
            (0..count).map(|_| DVector::zeros(len)).collect()
        };
        SoocFastSolver {
            options,
            n,
            nu: m,
            horizon,
            z: vectors(horizon + 1, nz),
            u: vectors(horizon, m),
            cand_z: vectors(horizon + 1, nz),
            cand_u: vectors(horizon, m),
            knots: (0..horizon)
                .map(|_| {
                    let e = crate::solver::sooc::MomentExpansion::for_dynamics(dynamics);
                    Knot::new(e, n, m, p, nz)
                })
                .collect(),
            terminal: CostDerivatives::new(nz, m),
            pi: (0..=horizon).map(|_| DMatrix::zeros(n, n)).collect(),
            lam: vectors(horizon + 1, n),
            grad: vectors(horizon, m),
            curvature: vectors(horizon, m),
            precond: Precond::new(n, m, horizon),
            cg: Some(Cg::new(horizon * m)),
            tmp: DMatrix::zeros(n, n),
        }
    }

    fn check(&self, problem: &SoocProblem, u: &[DVector<f64>]) -> Result<(), SoocError> {
        let got = (problem.dynamics.n(), problem.dynamics.nu(), problem.horizon);
        let want = (self.n, self.nu, self.horizon);
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
        if u.len() != self.horizon {
            return Err(SoocError::Length {
                what: "u_init",
                got: u.len(),
                want: self.horizon,
            });
        }
        if let Some(v) = u.iter().find(|v| v.len() != self.nu) {
            return Err(SoocError::Length {
                what: "a control of u_init",
                got: v.len(),
                want: self.nu,
            });
        }
        Ok(())
    }

    /// Takes `u` (clamped into the limits) as the current controls and rolls them out: `J`.
    fn start(&mut self, problem: &SoocProblem, u: &[DVector<f64>]) -> Result<f64, SoocError> {
        self.check(problem, u)?;
        for (dst, src) in self.u.iter_mut().zip(u) {
            dst.copy_from(src);
            problem.bounds.clamp(dst.as_mut_slice());
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

    /// The exact gradient `∇_{u_k} J` of the open-loop expected cost at `u` (clamped into the
    /// limits), by the adjoint of [`model`].
    pub fn gradient(
        &mut self,
        problem: &SoocProblem,
        u: &[DVector<f64>],
    ) -> Result<&[DVector<f64>], SoocError> {
        self.start(problem, u)?;
        self.model(problem, false);
        Ok(&self.grad)
    }

    /// Solves from `u_init` (clamped into the limits).
    pub fn solve(
        &mut self,
        problem: &SoocProblem,
        u_init: &[DVector<f64>],
    ) -> Result<SoocFastSolution, SoocError> {
        let start = Instant::now();
        let mut cost = self.start(problem, u_init)?;
        let scale = control_scales(problem.bounds);
        let mut cg = self.cg.take().expect("the step's vectors");
        let (mut iterations, mut cg_iterations) = (0, 0);
        let mut history = Vec::with_capacity(self.options.max_iterations);
        // The trust region's radius in the surrogate's norm `‖d‖_M` (∞ without one); the first
        // one the surrogate's own step (`‖M⁻¹g‖_M`).
        let mut radius = f64::NAN;
        let (stop, optimality) = loop {
            self.model(problem, true);
            self.active_set(problem.bounds, &scale, &mut cg);
            let mut mu = 0.0;
            while !self.factor(&cg.free, mu) {
                mu = (mu * 10.0).max(self.options.mu_min);
                if mu > self.options.mu_max {
                    break;
                }
            }
            let pg = self.projected_gradient(problem.bounds, &scale, cost, &cg.g0);
            if mu > self.options.mu_max {
                break (
                    SoocStop::RegularizationLimit,
                    self.optimality(pg, f64::INFINITY),
                );
            }
            if radius.is_nan() && !self.options.trust_region {
                radius = f64::INFINITY;
            }
            if radius.is_nan() {
                self.surrogate_step(&mut cg);
                radius = (-newton::dot(&cg.d, &cg.g0)).max(1e-300).sqrt();
            }
            let step = self.newton_cg(problem, &scale, cost, radius, &mut cg);
            cg_iterations += step.cg_iterations;
            let predicted = step.predicted / cost.abs().max(1e-300);
            let optimality = self.optimality(
                pg,
                if step.boundary {
                    f64::INFINITY
                } else {
                    predicted
                },
            );
            if optimality.met() {
                break (SoocStop::Converged, optimality);
            }
            if iterations >= self.options.max_iterations {
                break (SoocStop::MaxIterations, optimality);
            }
            let step_d = newton::dot(&cg.g0, &cg.d);
            let mut accepted = self.projected_search(problem, cost, &cg);
            if accepted.is_none() {
                // The scaled projected gradient path, a descent path whatever `H` is.
                self.gradient_step(&scale, &mut cg);
                accepted = self
                    .projected_search(problem, cost, &cg)
                    .map(|(c, _, slope)| (c, 0.0, slope));
            }
            let Some((c, alpha, slope)) = accepted else {
                break (SoocStop::RegularizationLimit, optimality);
            };
            // ρ = actual / predicted decrease of the full step; the radius follows it
            // (Nocedal & Wright Alg. 4.1): a quarter after a poor or backtracked step, doubled
            // after a good one on the boundary. The prediction is the unprojected step's,
            // scaled by the share of its first-order decrease that the box lets through, so
            // that a step cut by the bounds is not taken for a poor model.
            let full = -step_d;
            let through = if full > 0.0 {
                (-slope / full).clamp(0.0, 1.0)
            } else {
                1.0
            };
            let rho = (cost - c) / (step.predicted * through).max(1e-300);
            if radius.is_finite() {
                if alpha < 1.0 || rho < 0.25 {
                    radius = (0.25 * radius).max(1e-300);
                } else if rho > 0.75 && step.boundary {
                    radius = (2.0 * radius).max(2.0 * step.norm);
                }
            }
            std::mem::swap(&mut self.z, &mut self.cand_z);
            std::mem::swap(&mut self.u, &mut self.cand_u);
            cost = c;
            iterations += 1;
            history.push(c);
        };
        self.cg = Some(cg);
        Ok(SoocFastSolution {
            u: self.u.clone(),
            z: self.z.clone(),
            expected_cost: cost,
            iterations,
            cg_iterations,
            stop,
            optimality,
            solve_time: start.elapsed(),
            history,
        })
    }

    /// The gradient of the current point into `cg.g0` and the free controls into `cg.free`
    /// (Bertsekas' ε-active set): a control is held at a bound for the step when its gradient
    /// pushes it out and it is nearer to the bound than both a thousandth of its scale and the
    /// scaled gradient step `|g| / h` (`h` its model curvature, [`Self::factor`] having run
    /// before with every control free, or the previous step's).
    fn active_set(&self, bounds: &Bounds, scale: &[f64], cg: &mut Cg) {
        let m = self.nu;
        for (k, ((u, g), h)) in self
            .u
            .iter()
            .zip(&self.grad)
            .zip(&self.curvature)
            .enumerate()
        {
            for j in 0..m {
                let reach = if h[j] > 0.0 {
                    g[j].abs() / h[j]
                } else {
                    f64::INFINITY
                };
                let eps = (1e-3 * scale[j]).min(reach);
                let held = (u[j] <= bounds.lower[j] + eps && g[j] > 0.0)
                    || (u[j] >= bounds.upper[j] - eps && g[j] < 0.0);
                cg.g0[k * m + j] = g[j];
                cg.free[k * m + j] = !held;
            }
        }
    }

    fn optimality(&self, pg: f64, predicted: f64) -> Optimality {
        Optimality {
            projected_gradient: pg,
            predicted_decrease: predicted,
            gradient_tolerance: self.options.gradient_tolerance,
            decrease_tolerance: self.options.decrease_tolerance,
        }
    }

    /// `max_{k,j} s_{k,j} |Π(∇J)_{k,j}| / |J|`, `Π` zeroing the components that push out of the
    /// box at a bound, each scale capped at `√(2|J| / h)` with `h` the model's curvature of the
    /// control (see [`Optimality::projected_gradient`]).
    fn projected_gradient(&self, bounds: &Bounds, scale: &[f64], cost: f64, g0: &[f64]) -> f64 {
        let m = self.nu;
        let mut worst = 0.0_f64;
        for (k, (u, h)) in self.u.iter().zip(&self.curvature).enumerate() {
            for j in 0..m {
                let gj = g0[k * m + j];
                let blocked =
                    (u[j] <= bounds.lower[j] && gj > 0.0) || (u[j] >= bounds.upper[j] && gj < 0.0);
                if !blocked {
                    let s = if h[j] > 0.0 {
                        scale[j].min((2.0 * cost.abs() / h[j]).sqrt())
                    } else {
                        scale[j]
                    };
                    worst = worst.max(s * gj.abs());
                }
            }
        }
        worst / cost.abs().max(1e-300)
    }
}

/// Control scales: the box width where finite, else 1 (N m).
fn control_scales(bounds: &Bounds) -> [f64; MAX_QP] {
    let mut scale = [1.0; MAX_QP];
    for (s, (lo, hi)) in scale.iter_mut().zip(bounds.lower.iter().zip(&bounds.upper)) {
        if lo.is_finite() && hi.is_finite() && hi > lo {
            *s = hi - lo;
        }
    }
    scale
}
