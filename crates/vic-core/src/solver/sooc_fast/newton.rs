//! The step: projected truncated Newton (Newton–CG) in the space of all controls (Bertsekas,
//! "Projected Newton methods for optimization problems with simple constraints", SIAM J.
//! Control Optim. 1982; Nocedal & Wright, Numerical Optimization, Alg. 7.1 with a
//! preconditioner). The controls held at a bound by their gradient are fixed for the step; on
//! the free ones, preconditioned conjugate gradients solve `H_FF d = −g_F` with the exact
//! Hessian of `J` applied to a direction by central differences of the exact gradient
//! ([`super::model`], `O(n³)` per knot) and the surrogate's `M_FF⁻¹` ([`super::precond`]) as
//! the preconditioner. Then a backtracking line search on the true `J` along the projected path
//! `clamp(u + α d)`.

use super::{SoocFastSolver, SoocProblem, forward::rollout};
use crate::cost::Cost;
use crate::dynamics::Dynamics;

/// What the Newton–CG step found.
pub(super) struct Step {
    /// `−q(d) = −(gᵀd + ½ dᵀ H d)`, the decrease the quadratic model predicts for the step.
    pub(super) predicted: f64,
    /// Whether the step ends on the trust region's boundary (then it is not Newton's).
    pub(super) boundary: bool,
    /// `‖d‖_M` (before a boundary step).
    pub(super) norm: f64,
    /// CG iterations (each one Hessian-vector product: two gradients).
    pub(super) cg_iterations: usize,
}

/// Flat control-space vectors of the Newton–CG step (`k m + j`).
pub(super) struct Cg {
    pub(super) g0: Vec<f64>,
    pub(super) free: Vec<bool>,
    pub(super) d: Vec<f64>,
    r: Vec<f64>,
    y: Vec<f64>,
    p: Vec<f64>,
    hp: Vec<f64>,
    gm: Vec<f64>,
}

impl Cg {
    pub(super) fn new(len: usize) -> Self {
        let v = || vec![0.0; len];
        Cg {
            g0: v(),
            free: vec![true; len],
            d: v(),
            r: v(),
            y: v(),
            p: v(),
            hp: v(),
            gm: v(),
        }
    }
}

pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

impl SoocFastSolver {
    /// The exact gradient at `u + t·dir` (controls not clamped: the probe of a free control at
    /// its bound may leave the box by a round-off-sized step) into `out`; false if the moments
    /// blow up there. The current point's rollout and controls are kept.
    fn probe_gradient(
        &mut self,
        problem: &SoocProblem,
        dir: &[f64],
        t: f64,
        out: &mut [f64],
    ) -> bool {
        let m = self.nu;
        for (k, u) in self.cand_u.iter_mut().enumerate() {
            for j in 0..m {
                u[j] = self.u[k][j] + t * dir[k * m + j];
            }
        }
        self.cand_z[0].copy_from(&self.z[0]);
        if !rollout(problem, &mut self.cand_z, &self.cand_u).is_finite() {
            return false;
        }
        std::mem::swap(&mut self.z, &mut self.cand_z);
        std::mem::swap(&mut self.u, &mut self.cand_u);
        self.model(problem, false);
        std::mem::swap(&mut self.z, &mut self.cand_z);
        std::mem::swap(&mut self.u, &mut self.cand_u);
        for (k, g) in self.grad.iter().enumerate() {
            out[k * m..(k + 1) * m].copy_from_slice(g.as_slice());
        }
        true
    }

    /// `hp = H_FF p` by differences of the exact gradient along `p` (central with
    /// `central_differences`, else forward from the current gradient), the step `ε p` a
    /// fraction `fd_step` of each control's scale at its largest; false if a probe's moments
    /// blow up.
    fn hessian_product(&mut self, problem: &SoocProblem, scale: &[f64], cg: &mut Cg) -> bool {
        let m = self.nu;
        let mut reach = 0.0_f64;
        for (i, v) in cg.p.iter().enumerate() {
            reach = reach.max(v.abs() / scale[i % m]);
        }
        if reach == 0.0 {
            cg.hp.fill(0.0);
            return true;
        }
        let central = self.options.central_differences;
        let eps = self.options.fd_step / reach;
        let mut plus = std::mem::take(&mut cg.hp);
        let mut minus = std::mem::take(&mut cg.gm);
        let ok = self.probe_gradient(problem, &cg.p, eps, &mut plus)
            && (!central || self.probe_gradient(problem, &cg.p, -eps, &mut minus));
        if !central {
            minus.copy_from_slice(&cg.g0);
        }
        let width = if central { 2.0 * eps } else { eps };
        for ((h, mi), f) in plus.iter_mut().zip(&minus).zip(&cg.free) {
            *h = if *f { (*h - mi) / width } else { 0.0 };
        }
        cg.hp = plus;
        cg.gm = minus;
        ok && cg.hp.iter().all(|v| v.is_finite())
    }

    /// The Newton–CG step into `cg.d` from the gradient `cg.g0` on the free controls
    /// `cg.free`, with the preconditioner factorised ([`Self::factor`]), within the trust region
    /// `‖d‖_M ≤ radius` (Steihaug–Toint truncated CG: the `M`-norm is the preconditioner's, the
    /// iterates' norms grow monotonically and follow from CG's own scalars; Conn, Gould & Toint,
    /// Trust-Region Methods, Alg. 7.5.1). CG stops at a relative residual (in the `M⁻¹` norm) of
    /// `min(0.1, √δ)`, `δ = gᵀ M⁻¹ g / |J|` (superlinear near the optimum, Eisenstat & Walker's
    /// forcing term in spirit), at `max_cg` iterations, or on the boundary: where the region
    /// cuts the next iterate or a direction of non-positive curvature (followed to the boundary).
    pub(super) fn newton_cg(
        &mut self,
        problem: &SoocProblem,
        scale: &[f64],
        cost: f64,
        radius: f64,
        cg: &mut Cg,
    ) -> Step {
        cg.d.fill(0.0);
        for ((r, g), f) in cg.r.iter_mut().zip(&cg.g0).zip(&cg.free) {
            *r = if *f { *g } else { 0.0 };
        }
        self.precond.apply(&cg.r, &mut cg.y);
        for (p, y) in cg.p.iter_mut().zip(&cg.y) {
            *p = -y;
        }
        let mut ry = dot(&cg.r, &cg.y);
        let first = ry;
        let forcing = (ry / cost.abs().max(1e-300)).sqrt().min(0.1);
        // q(d) = gᵀd + ½ dᵀHd, and dᵀMd, dᵀMp, pᵀMp.
        let mut q = 0.0;
        let (mut dmd, mut dmp, mut pmp) = (0.0, 0.0, ry);
        let mut iterations = 0;
        let mut boundary = false;
        while ry > 0.0 && iterations < self.options.max_cg {
            let ok = self.hessian_product(problem, scale, cg);
            iterations += 1;
            let kappa = dot(&cg.p, &cg.hp);
            let alpha = ry / kappa;
            let curved = ok && kappa > 0.0 && kappa.is_finite();
            // The box: the iterate stops where a free control reaches its bound (as in TRON,
            // Lin & Moré 1999), the next step's active set holding it there.
            let wall = self.box_step(problem, scale, cg);
            if curved
                && alpha > wall
                && dmd + 2.0 * wall * dmp + wall * wall * pmp < radius * radius
            {
                for (d, p) in cg.d.iter_mut().zip(&cg.p) {
                    *d += wall * p;
                }
                q += -wall * ry + 0.5 * wall * wall * kappa;
                dmd += 2.0 * wall * dmp + wall * wall * pmp;
                boundary = true;
                break;
            }
            if !curved && !radius.is_finite() {
                // No region: the first direction (the surrogate's step) if it is the first,
                // else the iterate so far.
                if iterations == 1 {
                    cg.d.copy_from_slice(&cg.p);
                    q = -ry;
                }
                boundary = true;
                break;
            }
            if !curved || dmd + 2.0 * alpha * dmp + alpha * alpha * pmp >= radius * radius {
                // To the boundary: τ ≥ 0 with (d + τp)ᵀ M (d + τp) = radius².
                let disc = (dmp * dmp + pmp * (radius * radius - dmd)).max(0.0);
                let tau = (disc.sqrt() - dmp) / pmp;
                // q(d + τp) = q(d) + τ pᵀ(Hd + g) + ½ τ² κ, with pᵀ(Hd + g) = pᵀr = −rᵀy; a
                // probe that blew up leaves only the first-order term.
                q += -tau * ry
                    + if ok && kappa.is_finite() {
                        0.5 * tau * tau * kappa
                    } else {
                        0.0
                    };
                dmd = radius * radius;
                for (d, p) in cg.d.iter_mut().zip(&cg.p) {
                    *d += tau * p;
                }
                boundary = true;
                break;
            }
            for ((d, r), (p, hp)) in cg.d.iter_mut().zip(&mut cg.r).zip(cg.p.iter().zip(&cg.hp)) {
                *d += alpha * p;
                *r += alpha * hp;
            }
            q -= 0.5 * alpha * ry;
            dmd += 2.0 * alpha * dmp + alpha * alpha * pmp;
            self.precond.apply(&cg.r, &mut cg.y);
            let next = dot(&cg.r, &cg.y);
            if next <= forcing * forcing * first {
                break;
            }
            let beta = next / ry;
            for (p, y) in cg.p.iter_mut().zip(&cg.y) {
                *p = beta * *p - y;
            }
            dmp = beta * (dmp + alpha * pmp);
            pmp = next + beta * beta * pmp;
            ry = next;
        }
        Step {
            predicted: -q,
            cg_iterations: iterations,
            boundary,
            norm: dmd.max(0.0).sqrt(),
        }
    }

    /// The largest `t` with `u + d + t p` in the box over the free controls that are more than
    /// a millionth of their scale inside it (those nearer are left to the projection).
    fn box_step(&self, problem: &SoocProblem, scale: &[f64], cg: &Cg) -> f64 {
        let m = self.nu;
        let (lo, hi) = (&problem.bounds.lower, &problem.bounds.upper);
        let mut t = f64::INFINITY;
        for (i, (p, d)) in cg.p.iter().zip(&cg.d).enumerate() {
            let (k, j) = (i / m, i % m);
            if !cg.free[i] || *p == 0.0 {
                continue;
            }
            let v = self.u[k][j] + d;
            let tiny = 1e-6 * scale[j];
            if *p < 0.0 && v - lo[j] > tiny {
                t = t.min((lo[j] - v) / p);
            } else if *p > 0.0 && hi[j] - v > tiny {
                t = t.min((hi[j] - v) / p);
            }
        }
        t.max(0.0)
    }

    /// `cg.d = −g / h` on every control (`h` its model curvature, else its scale squared): the
    /// scaled gradient, whose projected path `clamp(u + α d)` descends for small `α` whatever
    /// the bounds and `H` are (Bertsekas 1982).
    pub(super) fn gradient_step(&mut self, scale: &[f64], cg: &mut Cg) {
        let m = self.nu;
        for (i, (d, g)) in cg.d.iter_mut().zip(&cg.g0).enumerate() {
            let h = self.curvature[i / m][i % m];
            let w = if h > 0.0 {
                1.0 / h
            } else {
                scale[i % m] * scale[i % m]
            };
            *d = -g * w;
        }
    }

    /// `cg.d = −M_FF⁻¹ g_F`, the surrogate's own step.
    pub(super) fn surrogate_step(&mut self, cg: &mut Cg) {
        for ((r, g), f) in cg.r.iter_mut().zip(&cg.g0).zip(&cg.free) {
            *r = if *f { *g } else { 0.0 };
        }
        self.precond.apply(&cg.r, &mut cg.d);
        cg.d.iter_mut().for_each(|v| *v = -*v);
    }

    /// Backtracking (halving, 30 tries) along the step with the surrogate's feedback on the
    /// mean, `u_k(α) = clamp(u_k + α d_k + K_k (m'_k − m_k − α δm_k))`, `δm` the mean's linear
    /// response to `d` and `K_k` the Riccati gains of [`super::precond`]: to first order in `α`
    /// the open-loop step `u + α d` (the same model, the same fixed point), but the mean's
    /// drift from its linear prediction on an unstable plant is fed back rather than left to
    /// grow (the forward pass of iLQR/DDP). Accepted when `J` falls by at least `10⁻⁴` of its
    /// first-order change `gᵀ (u(α) − u)`. The candidate holds the accepted rollout; its `J`,
    /// `α` and that first-order change.
    pub(super) fn projected_search(
        &mut self,
        problem: &SoocProblem,
        cost: f64,
        cg: &Cg,
    ) -> Option<(f64, f64, f64)> {
        let (n, m) = (self.n, self.nu);
        let mut alpha = 1.0;
        for _ in 0..30 {
            let mut slope = 0.0;
            self.cand_z[0].copy_from(&self.z[0]);
            self.precond.reset_linear();
            let mut c = 0.0;
            for k in 0..self.horizon {
                let (head, tail) = self.cand_z.split_at_mut(k + 1);
                let u = &mut self.cand_u[k];
                for j in 0..m {
                    u[j] = self.u[k][j] + alpha * cg.d[k * m + j];
                }
                self.precond
                    .feedback(k, head[k].rows(0, n), self.z[k].rows(0, n), alpha, u);
                problem.bounds.clamp(u.as_mut_slice());
                for j in 0..m {
                    slope += cg.g0[k * m + j] * (u[j] - self.u[k][j]);
                }
                self.precond.advance_linear(k, &cg.d[k * m..(k + 1) * m]);
                c += problem.cost.running(k, head[k].as_slice(), u.as_slice());
                problem
                    .dynamics
                    .step(k, head[k].as_slice(), u.as_slice(), tail[0].as_mut_slice());
                if !c.is_finite() || tail[0].iter().any(|v| !v.is_finite()) {
                    c = f64::INFINITY;
                    break;
                }
            }
            if c.is_finite() {
                c += problem.cost.terminal(self.cand_z[self.horizon].as_slice());
            }
            if c.is_finite() && c < cost && c - cost <= 1e-4 * slope {
                return Some((c, alpha, slope));
            }
            alpha *= 0.5;
        }
        None
    }
}
