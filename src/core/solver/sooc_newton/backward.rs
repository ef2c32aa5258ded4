//! The backward pass of the stagewise Newton step: per knot from the last, the Q-function
//! (with the costate-weighted curvature of the moment step for Newton), the box-limited stage
//! QP (Tassa, Mansard & Todorov 2014), the gains and the value update.

use super::SoocSolver;
use crate::core::solver::Bounds;
use crate::core::solver::boxqp::{MAX_QP, QpSolution, QpStatus, solve_box_qp};
use nalgebra::{DMatrix, DVector};

/// Scratch of the backward pass.
pub(super) struct Backward {
    v: DMatrix<f64>,
    vv: DVector<f64>,
    va: DMatrix<f64>,
    vb: DMatrix<f64>,
    qzz: DMatrix<f64>,
    quz: DMatrix<f64>,
    quu: DMatrix<f64>,
    qz: DVector<f64>,
    qu: DVector<f64>,
    hzz: DMatrix<f64>,
    huz: DMatrix<f64>,
    huu: DMatrix<f64>,
    kt_quu: DMatrix<f64>,
    t_mz: DMatrix<f64>,
    /// The open-loop second derivative of the cost-to-go in `z` (every later control held):
    /// `S_k = ℓ_zz + H_zz + Aᵀ S_{k+1} A`, for the diagonal of `∇²J`.
    s: DMatrix<f64>,
    sa: DMatrix<f64>,
    sb: DMatrix<f64>,
}

impl Backward {
    pub(super) fn new(nz: usize, m: usize) -> Self {
        let zm = |r, c| DMatrix::zeros(r, c);
        Backward {
            v: zm(nz, nz),
            vv: DVector::zeros(nz),
            va: zm(nz, nz),
            vb: zm(nz, m),
            qzz: zm(nz, nz),
            quz: zm(m, nz),
            quu: zm(m, m),
            qz: DVector::zeros(nz),
            qu: DVector::zeros(m),
            hzz: zm(nz, nz),
            huz: zm(m, nz),
            huu: zm(m, m),
            kt_quu: zm(nz, m),
            t_mz: zm(m, nz),
            s: zm(nz, nz),
            sa: zm(nz, nz),
            sb: zm(nz, m),
        }
    }

    /// `V = Q_zz + Kᵀ Q_uu K + Kᵀ Q_uz + Q_uzᵀ K`, `v = Q_z + Kᵀ Q_uu k + Kᵀ Q_u + Q_uzᵀ k`
    /// (symmetrised), and the stage's predicted decrease terms `(kᵀ Q_u, ½ kᵀ Q_uu k)` with the
    /// unregularised model.
    fn value_update(&mut self, ff: &DVector<f64>, gain: &DMatrix<f64>) -> (f64, f64) {
        let m = ff.len();
        let mut quu_k = 0.0;
        for i in 0..m {
            for j in 0..m {
                quu_k += ff[i] * self.quu[(i, j)] * ff[j];
            }
        }
        let dv = (ff.dot(&self.qu), 0.5 * quu_k);
        self.kt_quu.gemm_tr(1.0, gain, &self.quu, 0.0);
        self.t_mz.copy_from(&self.quz);
        self.t_mz.gemm(1.0, &self.quu, gain, 1.0);
        self.v.copy_from(&self.qzz);
        self.v.gemm_tr(1.0, gain, &self.t_mz, 1.0);
        self.v.gemm_tr(1.0, &self.quz, gain, 1.0);
        self.vv.copy_from(&self.qz);
        self.vv.gemv(1.0, &self.kt_quu, ff, 1.0);
        self.vv.gemv_tr(1.0, gain, &self.qu, 1.0);
        self.vv.gemv_tr(1.0, &self.quz, ff, 1.0);
        let nz = self.v.nrows();
        for i in 0..nz {
            for j in 0..i {
                let s = 0.5 * (self.v[(i, j)] + self.v[(j, i)]);
                self.v[(i, j)] = s;
                self.v[(j, i)] = s;
            }
        }
        dv
    }
}

impl SoocSolver {
    /// The Riccati recursion of the Newton step with box-limited stage QPs; the predicted
    /// decrease terms `(Σ kᵀ Q_u, Σ ½ kᵀ Q_uu k)`, or `None` if some stage QP is not convex at
    /// this μ.
    pub(super) fn backward(
        &mut self,
        bounds: &Bounds,
        mu: f64,
        newton: bool,
    ) -> Option<(f64, f64)> {
        let h = self.horizon;
        self.bw.v.copy_from(&self.derivs[h].lxx);
        self.bw.vv.copy_from(&self.derivs[h].lx);
        let (mut dv1, mut dv2) = (0.0, 0.0);
        for k in (0..h).rev() {
            self.q_function(k, newton);
            self.stage_policy(k, bounds, mu)?;
            let (d1, d2) = self.bw.value_update(&self.ff[k], &self.gains[k]);
            dv1 += d1;
            dv2 += d2;
        }
        Some((dv1, dv2))
    }

    /// The diagonal of the exact `∇²J` into `hess_diag`: per knot from the last,
    /// `∂²J/∂u_{k,j}²` with every other control held, `ℓ_uu + H_uu + Bᵀ S_{k+1} B`, and
    /// `S_k = ℓ_zz + H_zz + Aᵀ S_{k+1} A` (`H` the costate-weighted curvature of the moment step;
    /// needs the Newton model's second-order expansion at the current controls). A pass of its
    /// own, run only when the convergence test needs it.
    pub(super) fn hessian_diagonal_pass(&mut self) {
        let h = self.horizon;
        self.bw.s.copy_from(&self.derivs[h].lxx);
        for k in (0..h).rev() {
            let bw = &mut self.bw;
            self.expansions[k].curvature(
                self.lam[k + 1].as_slice(),
                &mut bw.hzz,
                &mut bw.huz,
                &mut bw.huu,
            );
            self.open_loop_diagonal(k);
        }
    }

    /// One knot of [`Self::hessian_diagonal_pass`], with `H` in the scratch.
    fn open_loop_diagonal(&mut self, k: usize) {
        let bw = &mut self.bw;
        let e = &self.expansions[k];
        let d = &self.derivs[k];
        bw.sb.gemm(1.0, &bw.s, &e.b, 0.0);
        let diag = &mut self.hess_diag[k];
        for j in 0..diag.len() {
            diag[j] = d.luu[(j, j)] + bw.huu[(j, j)] + e.b.column(j).dot(&bw.sb.column(j));
        }
        bw.sa.gemm(1.0, &bw.s, &e.a, 0.0);
        bw.s.copy_from(&d.lxx);
        bw.s += &bw.hzz;
        bw.s.gemm_tr(1.0, &e.a, &bw.sa, 1.0);
    }

    /// `Q` at knot `k` from the value `(V, v)` of knot `k + 1`: the Gauss–Newton terms plus, for
    /// Newton, the costate-weighted curvature of the moment step.
    fn q_function(&mut self, k: usize, newton: bool) {
        let bw = &mut self.bw;
        let e = &mut self.expansions[k];
        let d = &self.derivs[k];
        if newton {
            e.curvature(
                self.lam[k + 1].as_slice(),
                &mut bw.hzz,
                &mut bw.huz,
                &mut bw.huu,
            );
        } else {
            bw.hzz.fill(0.0);
            bw.huz.fill(0.0);
            bw.huu.fill(0.0);
        }
        bw.va.gemm(1.0, &bw.v, &e.a, 0.0);
        bw.vb.gemm(1.0, &bw.v, &e.b, 0.0);
        bw.qzz.copy_from(&d.lxx);
        bw.qzz += &bw.hzz;
        bw.qzz.gemm_tr(1.0, &e.a, &bw.va, 1.0);
        bw.quz.copy_from(&d.lux);
        bw.quz += &bw.huz;
        bw.quz.gemm_tr(1.0, &e.b, &bw.va, 1.0);
        bw.quu.copy_from(&d.luu);
        bw.quu += &bw.huu;
        bw.quu.gemm_tr(1.0, &e.b, &bw.vb, 1.0);
        bw.qz.copy_from(&d.lx);
        bw.qz.gemv_tr(1.0, &e.a, &bw.vv, 1.0);
        bw.qu.copy_from(&d.lu);
        bw.qu.gemv_tr(1.0, &e.b, &bw.vv, 1.0);
    }

    /// The stage QP on the regularised `Q_uu` within the box around `u_k` into `ff[k]`, and the
    /// gains: free rows `−(Q_uu,ff)⁻¹ Q_uz,f`, clamped rows 0. `None` when not convex.
    fn stage_policy(&mut self, k: usize, bounds: &Bounds, mu: f64) -> Option<()> {
        let m = self.nu;
        let bw = &self.bw;
        let d = &self.derivs[k];
        let mut lo = [0.0; MAX_QP];
        let mut hi = [0.0; MAX_QP];
        let mut reg = [0.0; MAX_QP];
        for j in 0..m {
            lo[j] = bounds.lower[j] - self.u[k][j];
            hi[j] = bounds.upper[j] - self.u[k][j];
            // μ scales the control's Gauss–Newton curvature `ℓ_uu + Bᵀ V B` (the diagonal of
            // Q_uu without the costate term), not its own cost curvature `ℓ_uu` alone: with
            // w_st = 1e-4 the stiffness's ℓ_uu is ~1e-4 of what a unit of stiffness does to
            // the expected cost through the covariance, so a μ relative to ℓ_uu could not
            // convexify an indefinite Newton model before μ reached its limit, and the solver
            // fell back to Gauss–Newton steps that crawl (the VSA plans stalled that way).
            let gauss_newton = (bw.quu[(j, j)] - bw.huu[(j, j)]).abs();
            reg[j] = mu * gauss_newton.max(d.luu[(j, j)].abs()).max(1e-12);
        }
        let quu = &bw.quu;
        let hq = |i: usize, j: usize| {
            0.5 * (quu[(i, j)] + quu[(j, i)]) + if i == j { reg[i] } else { 0.0 }
        };
        let qp = solve_box_qp(
            hq,
            bw.qu.as_slice(),
            &lo[..m],
            &hi[..m],
            self.ff[k].as_slice(),
        );
        if qp.status == QpStatus::NotPositiveDefinite {
            return None;
        }
        self.ff[k].copy_from_slice(&qp.x[..m]);
        feedback_gains(&qp, &bw.quz, &mut self.gains[k])
    }
}

/// `K` with free rows `−(Q_uu,ff)⁻¹ Q_uz,f` (the QP's factor of the free block) and clamped
/// rows 0; `None` if the free block has no factor.
fn feedback_gains(qp: &QpSolution, quz: &DMatrix<f64>, gain: &mut DMatrix<f64>) -> Option<()> {
    let (m, nz) = gain.shape();
    gain.fill(0.0);
    let mut free = [0usize; MAX_QP];
    let mut nf = 0;
    for j in 0..m {
        if qp.free[j] {
            free[nf] = j;
            nf += 1;
        }
    }
    if nf == 0 {
        return Some(());
    }
    let factor = qp.factor.as_ref()?;
    let mut col = [0.0; MAX_QP];
    for c in 0..nz {
        for (i, &j) in free[..nf].iter().enumerate() {
            col[i] = -quz[(j, c)];
        }
        factor.solve(&mut col[..nf]);
        for (i, &j) in free[..nf].iter().enumerate() {
            gain[(j, c)] = col[i];
        }
    }
    Some(())
}
