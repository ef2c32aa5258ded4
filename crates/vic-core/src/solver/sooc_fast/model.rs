//! The model of one iteration at the current controls: the step's first derivatives at every
//! knot, the covariance adjoint `Π_k` (the exact sensitivity of the expected cost-to-go to
//! `P_k`), and each knot's surrogate stage cost `ℓ̃_k(m, u) = ℓ(m, u) + tr(Π_{k+1} P⁺(m, u))`
//! with `P_k` and `Π_{k+1}` frozen: its gradient (exact) and its curvature (the part of
//! `P⁺ = A P Aᵀ + W` that is bilinear in the first derivatives). Then the mean's costates and
//! the exact gradient of `J`. All as n×n products.

use super::{SoocFastSolver, SoocProblem};
use crate::cost::{Cost, CostDerivatives};
use crate::dense::multiply;
use crate::dynamics::NoiseKind;
use crate::solver::sooc::{MomentExpansion, costate_matrix};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// One knot's expansion and its surrogate stage terms.
pub(super) struct Knot {
    pub(super) e: MomentExpansion,
    pub(super) d: CostDerivatives,
    /// `∂ tr(Π_{k+1} P⁺)/∂v_j`, `v = (m, u)`: the covariance's part of the exact gradient.
    pub(super) s: DVector<f64>,
    /// The surrogate's curvature of `tr(Π_{k+1} P⁺)` over `v` (nv×nv, positive semidefinite):
    /// `2 tr(Π dA_a P dA_bᵀ) + Σ_i 2 dc_{i,a}ᵀ Π dc_{i,b} + 2 tr(Π dCx_{i,a} P dCx_{i,b}ᵀ)`.
    pub(super) g: DMatrix<f64>,
    t1: DMatrix<f64>,
    t2: DMatrix<f64>,
    /// `Π dA_b P` per direction `b`.
    y: Vec<DMatrix<f64>>,
    /// `Π dc_b` per direction (n×p).
    yc: Vec<DMatrix<f64>>,
    /// `Π C` (n×p).
    pc: DMatrix<f64>,
}

impl Knot {
    pub(super) fn new(e: MomentExpansion, n: usize, m: usize, p: usize, nz: usize) -> Self {
        let nv = n + m;
        let z = |r, c| DMatrix::zeros(r, c);
        Knot {
            e,
            d: CostDerivatives::new(nz, m),
            s: DVector::zeros(nv),
            g: z(nv, nv),
            t1: z(n, n),
            t2: z(n, n),
            y: (0..nv).map(|_| z(n, n)).collect(),
            yc: (0..nv).map(|_| z(n, p)).collect(),
            pc: z(n, p),
        }
    }

    /// The surrogate's gradient `s` and (with `curvature`) curvature `g` with the next knot's
    /// adjoint `pi`.
    fn stage_terms(&mut self, pi: &DMatrix<f64>, curvature: bool) {
        let fs = self.e.flow_sensitivity();
        let (lin, p) = (fs.lin, fs.p);
        let nv = fs.da.len();
        // d tr(Π A P Aᵀ)/dv_j = 2 tr(Π dA_j P Aᵀ) = 2 Σ dA_j ∘ (Π A P).
        multiply(&mut self.t1, pi, &lin.a, false);
        multiply(&mut self.t2, &self.t1, p, false);
        for j in 0..nv {
            self.s[j] = 2.0 * fs.da[j].dot(&self.t2);
        }
        if !curvature {
            return self.noise_gradient(pi);
        }
        for b in 0..nv {
            multiply(&mut self.t1, pi, &fs.da[b], false);
            multiply(&mut self.y[b], &self.t1, p, false);
        }
        for a in 0..nv {
            for b in a..nv {
                let v = 2.0 * fs.da[a].dot(&self.y[b]);
                self.g[(a, b)] = v;
                self.g[(b, a)] = v;
            }
        }
        if lin.noise == NoiseKind::None {
            return;
        }
        // d tr(Π c cᵀ)/dv_j = 2 Σ_i dc_{i,j} ∘ Π c_i; its bilinear part 2 dc_aᵀ Π dc_b.
        multiply(&mut self.pc, pi, &lin.c, false);
        for j in 0..nv {
            self.s[j] += 2.0 * fs.dc[j].dot(&self.pc);
            multiply(&mut self.yc[j], pi, &fs.dc[j], false);
        }
        for a in 0..nv {
            for b in a..nv {
                let v = 2.0 * fs.dc[a].dot(&self.yc[b]);
                self.g[(a, b)] += v;
                if a != b {
                    self.g[(b, a)] += v;
                }
            }
        }
        if !fs.curved_noise {
            return;
        }
        // A noise gain nonlinear in the state: `Cx_i` moves with `v`, `tr(Π Cx P Cxᵀ)` as `A`.
        for (i, cx) in lin.cx.iter().enumerate() {
            multiply(&mut self.t1, pi, cx, false);
            multiply(&mut self.t2, &self.t1, p, false);
            for j in 0..nv {
                self.s[j] += 2.0 * fs.dcx[j][i].dot(&self.t2);
            }
            for b in 0..nv {
                multiply(&mut self.t1, pi, &fs.dcx[b][i], false);
                multiply(&mut self.t2, &self.t1, p, false);
                for a in 0..nv {
                    self.g[(a, b)] += 2.0 * fs.dcx[a][i].dot(&self.t2);
                }
            }
        }
        // Symmetric in exact arithmetic; keep it so to the bit.
        for a in 0..nv {
            for b in a + 1..nv {
                let v = 0.5 * (self.g[(a, b)] + self.g[(b, a)]);
                self.g[(a, b)] = v;
                self.g[(b, a)] = v;
            }
        }
    }
}

impl Knot {
    /// The noise's part of the surrogate's gradient `s` alone (what [`Knot::stage_terms`] adds
    /// to it besides the curvature).
    fn noise_gradient(&mut self, pi: &DMatrix<f64>) {
        let fs = self.e.flow_sensitivity();
        let (lin, p) = (fs.lin, fs.p);
        let nv = fs.da.len();
        if lin.noise == NoiseKind::None {
            return;
        }
        multiply(&mut self.pc, pi, &lin.c, false);
        for j in 0..nv {
            self.s[j] += 2.0 * fs.dc[j].dot(&self.pc);
        }
        if !fs.curved_noise {
            return;
        }
        for (i, cx) in lin.cx.iter().enumerate() {
            multiply(&mut self.t1, pi, cx, false);
            multiply(&mut self.t2, &self.t1, p, false);
            for j in 0..nv {
                self.s[j] += 2.0 * fs.dcx[j][i].dot(&self.t2);
            }
        }
    }
}

impl SoocFastSolver {
    /// The model at the current controls and their rollout `z`: expansions (in parallel), the
    /// adjoint `Π`, the stage terms (in parallel), the mean's costates and the exact gradient.
    /// Without `curvature` only the gradient (the surrogate's stage curvature `g` is left as it
    /// was).
    pub(super) fn model(&mut self, problem: &SoocProblem, curvature: bool) {
        let (n, h) = (self.n, self.horizon);
        let (z, u) = (&self.z, &self.u);
        self.knots.par_iter_mut().enumerate().for_each(|(k, kn)| {
            let (zk, uk) = (z[k].as_slice(), u[k].as_slice());
            problem.dynamics.expand_matrices(k, zk, uk, &mut kn.e);
            problem.cost.running_derivatives(k, zk, uk, &mut kn.d);
        });
        problem
            .cost
            .terminal_derivatives(self.z[h].as_slice(), &mut self.terminal);
        // Π_N = ½ g_xx; Π_k = ½ ℓ_xx + A_kᵀ Π_{k+1} A_k + Σ_i Cx_iᵀ Π_{k+1} Cx_i: the expected
        // cost is linear in P, with weights `tr(½ ℓ_xx P)`, and P⁺ linear in P through these.
        costate_matrix(n, &self.terminal.lx.as_slice()[n..], &mut self.pi[h]);
        for k in (0..h).rev() {
            let (head, tail) = self.pi.split_at_mut(k + 1);
            let (pk, next) = (&mut head[k], &tail[0]);
            let kn = &mut self.knots[k];
            costate_matrix(n, &kn.d.lx.as_slice()[n..], pk);
            let lin = kn.e.flow_sensitivity().lin;
            multiply(&mut self.tmp, next, &lin.a, false);
            pk.gemm_tr(1.0, &lin.a, &self.tmp, 1.0);
            if lin.noise == NoiseKind::Dependent {
                for cx in &lin.cx {
                    multiply(&mut self.tmp, next, cx, false);
                    pk.gemm_tr(1.0, cx, &self.tmp, 1.0);
                }
            }
        }
        self.knots
            .par_iter_mut()
            .zip(self.pi[1..].par_iter())
            .for_each(|(kn, pi)| kn.stage_terms(pi, curvature));
        // The mean's costates of the surrogate problem, λ_N = g_m, λ_k = ℓ̃_m + Aᵀ λ_{k+1},
        // equal the true ones (the stage terms carry P⁺'s dependence on m), so
        // `∇_{u_k} J = ℓ̃_u + Bᵀ λ_{k+1}` is the exact gradient.
        self.lam[h].copy_from(&self.terminal.lx.rows(0, n));
        for k in (0..h).rev() {
            let (head, tail) = self.lam.split_at_mut(k + 1);
            let next = &tail[0];
            let kn = &self.knots[k];
            let lin = kn.e.flow_sensitivity().lin;
            let lk = &mut head[k];
            lk.copy_from(&kn.d.lx.rows(0, n));
            *lk += &kn.s.rows(0, n);
            lk.gemv_tr(1.0, &lin.a, next, 1.0);
            let g = &mut self.grad[k];
            g.copy_from(&kn.d.lu);
            *g += &kn.s.rows(n, self.nu);
            g.gemv_tr(1.0, &lin.b, next, 1.0);
        }
    }
}
