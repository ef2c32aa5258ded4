//! The backward pass on the mean alone (dimension n): control-limited iLQR (Tassa, Mansard &
//! Todorov 2014) on the surrogate stage costs of [`super::model`], with their exact gradients
//! and their covariance curvature, and the Gauss–Newton model of the mean's step.

use super::SoocFastSolver;
use crate::dense::{multiply, zero};
use crate::solver::Bounds;
use crate::solver::boxqp::{MAX_QP, QpSolution, QpStatus, SmallCholesky, solve_box_qp};
use nalgebra::{DMatrix, DVector};

/// Scratch of the backward pass.
pub(super) struct Back {
    vx: DVector<f64>,
    vxx: DMatrix<f64>,
    qx: DVector<f64>,
    qu: DVector<f64>,
    qxx: DMatrix<f64>,
    quu: DMatrix<f64>,
    qux: DMatrix<f64>,
    /// `V_xx A` (n×n), `V_xx B` (n×m), `Q_uu K + Q_ux` (m×n).
    vxa: DMatrix<f64>,
    vxb: DMatrix<f64>,
    t_mn: DMatrix<f64>,
    w: DVector<f64>,
}

impl Back {
    pub(super) fn new(n: usize, m: usize) -> Self {
        Back {
            vx: DVector::zeros(n),
            vxx: DMatrix::zeros(n, n),
            qx: DVector::zeros(n),
            qu: DVector::zeros(m),
            qxx: DMatrix::zeros(n, n),
            quu: DMatrix::zeros(m, m),
            qux: DMatrix::zeros(m, n),
            vxa: DMatrix::zeros(n, n),
            vxb: DMatrix::zeros(n, m),
            t_mn: DMatrix::zeros(m, n),
            w: DVector::zeros(m),
        }
    }
}

/// The backward pass's prediction `ΔJ(α) = α dv1 + α² dv2`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Prediction {
    pub(super) dv1: f64,
    pub(super) dv2: f64,
}

impl SoocFastSolver {
    /// One backward pass with relative regularisation `mu` (each control's `Q_uu` diagonal
    /// raised by `mu` times itself): feedforward steps `ff` within the box, mean feedback gains,
    /// and each control's model curvature (`Q_uu`'s diagonal before regularisation) into
    /// `curvature`. `None` if a stage QP is not convex.
    pub(super) fn backward(&mut self, bounds: &Bounds, mu: f64) -> Option<Prediction> {
        let (n, m, h) = (self.n, self.nu, self.horizon);
        let bw = &mut self.back;
        bw.vx.copy_from(&self.terminal.lx.rows(0, n));
        bw.vxx.copy_from(&self.terminal.lxx.view((0, 0), (n, n)));
        let (mut dv1, mut dv2) = (0.0, 0.0);
        for k in (0..h).rev() {
            let kn = &self.knots[k];
            let lin = kn.e.flow_sensitivity().lin;
            let d = &kn.d;
            // Q_x = ℓ̃_x + Aᵀ V_x, Q_u = ℓ̃_u + Bᵀ V_x.
            bw.qx.copy_from(&d.lx.rows(0, n));
            bw.qx += &kn.s.rows(0, n);
            bw.qx.gemv_tr(1.0, &lin.a, &bw.vx, 1.0);
            bw.qu.copy_from(&d.lu);
            bw.qu += &kn.s.rows(n, m);
            bw.qu.gemv_tr(1.0, &lin.b, &bw.vx, 1.0);
            // Second derivatives: the cost's, the covariance's curvature, the mean's Gauss–Newton.
            multiply(&mut bw.vxa, &bw.vxx, &lin.a, false);
            multiply(&mut bw.vxb, &bw.vxx, &lin.b, false);
            bw.qxx.copy_from(&d.lxx.view((0, 0), (n, n)));
            bw.qxx += &kn.g.view((0, 0), (n, n));
            bw.qxx.gemm_tr(1.0, &lin.a, &bw.vxa, 1.0);
            bw.quu.copy_from(&d.luu);
            bw.quu += &kn.g.view((n, n), (m, m));
            bw.quu.gemm_tr(1.0, &lin.b, &bw.vxb, 1.0);
            bw.qux.copy_from(&d.lux.view((0, 0), (m, n)));
            bw.qux += &kn.g.view((n, 0), (m, n));
            bw.qux.gemm_tr(1.0, &lin.b, &bw.vxa, 1.0);
            // Relative Levenberg–Marquardt: independent of the controls' units.
            let mut lo = [0.0; MAX_QP];
            let mut hi = [0.0; MAX_QP];
            for j in 0..m {
                self.curvature[k][j] = bw.quu[(j, j)];
                lo[j] = bounds.lower[j] - self.u[k][j];
                hi[j] = bounds.upper[j] - self.u[k][j];
            }
            for i in 0..m {
                for j in 0..i {
                    let v = 0.5 * (bw.quu[(i, j)] + bw.quu[(j, i)]);
                    bw.quu[(i, j)] = v;
                    bw.quu[(j, i)] = v;
                }
                bw.quu[(i, i)] += mu * bw.quu[(i, i)].abs().max(1e-12);
            }
            let mut factor = SmallCholesky::EMPTY;
            let quu = &bw.quu;
            let qp = solve_box_qp(
                |i, j| quu[(i, j)],
                bw.qu.as_slice(),
                &lo[..m],
                &hi[..m],
                self.ff[k].as_slice(),
                &mut factor,
            );
            if qp.status == QpStatus::NotPositiveDefinite {
                return None;
            }
            self.ff[k].copy_from_slice(&qp.x[..m]);
            feedback_gains(&qp, &factor, &bw.qux, &mut self.gains[k])?;
            let (kf, gain) = (&self.ff[k], &self.gains[k]);
            // w = Q_uu k + Q_u; V_x = Q_x + Kᵀ w + Q_uxᵀ k.
            bw.w.copy_from(&bw.qu);
            bw.w.gemv(1.0, &bw.quu, kf, 1.0);
            dv1 += kf.dot(&bw.qu);
            dv2 += 0.5 * (kf.dot(&bw.w) - kf.dot(&bw.qu));
            bw.vx.copy_from(&bw.qx);
            bw.vx.gemv_tr(1.0, gain, &bw.w, 1.0);
            bw.vx.gemv_tr(1.0, &bw.qux, kf, 1.0);
            // V_xx = Q_xx + Kᵀ (Q_uu K + Q_ux) + Q_uxᵀ K, symmetrised.
            bw.t_mn.copy_from(&bw.qux);
            multiply(&mut bw.t_mn, &bw.quu, gain, true);
            bw.vxx.copy_from(&bw.qxx);
            bw.vxx.gemm_tr(1.0, gain, &bw.t_mn, 1.0);
            bw.vxx.gemm_tr(1.0, &bw.qux, gain, 1.0);
            for i in 0..n {
                for j in 0..i {
                    let v = 0.5 * (bw.vxx[(i, j)] + bw.vxx[(j, i)]);
                    bw.vxx[(i, j)] = v;
                    bw.vxx[(j, i)] = v;
                }
            }
        }
        Some(Prediction { dv1, dv2 })
    }
}

/// `K` with free rows `−(Q_uu,ff)⁻¹ Q_ux,f` (the QP's factor of the free block) and clamped
/// rows 0; `None` if the free block has no factor.
fn feedback_gains(
    qp: &QpSolution,
    factor: &SmallCholesky,
    qux: &DMatrix<f64>,
    gain: &mut DMatrix<f64>,
) -> Option<()> {
    let (m, n) = gain.shape();
    zero(gain);
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
    if !qp.factored {
        return None;
    }
    let mut col = [0.0; MAX_QP];
    for c in 0..n {
        for (i, &j) in free[..nf].iter().enumerate() {
            col[i] = -qux[(j, c)];
        }
        factor.solve(&mut col[..nf]);
        for (i, &j) in free[..nf].iter().enumerate() {
            gain[(j, c)] = col[i];
        }
    }
    Some(())
}
