//! The preconditioner of the Newton–CG step: the inverse of the Hessian `M` of the LQ surrogate
//! of [`super::model`] (the mean's dynamics linearised, each knot's stage curvature including
//! the covariance's `2 tr(Π dA_a P dA_bᵀ)`), condensed onto the controls and restricted to the
//! free ones. `M` is symmetric positive definite (a sum of positive semidefinite stage terms and
//! the costs' control weights), and a Riccati factorisation applies `M_FF⁻¹` to a control-space
//! residual in `O(N (n² + n m))` without forming `M`: minimising `½ δᵀ M δ + rᵀ δ` over the
//! free controls subject to `δm⁺ = A δm + B δu` gives `δ = −M_FF⁻¹ r`.

use super::SoocFastSolver;
use crate::dense::{multiply, zero};
use crate::solver::boxqp::{MAX_QP, SmallCholesky};
use nalgebra::{DMatrix, DVector};

/// One knot's part of the factorisation.
pub(super) struct PrecondKnot {
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    /// `Q_uu` (regularised) and `Q_ux` of the surrogate's Riccati recursion.
    quu: DMatrix<f64>,
    qux: DMatrix<f64>,
    /// Feedback gains of the free controls (clamped rows 0).
    gain: DMatrix<f64>,
    factor: SmallCholesky,
    /// The free controls' indices.
    free: [usize; MAX_QP],
    nf: usize,
    /// The feedforward of the last application.
    kff: DVector<f64>,
}

/// Scratch of the factorisation and its application.
pub(super) struct Precond {
    pub(super) knots: Vec<PrecondKnot>,
    vxx: DMatrix<f64>,
    qxx: DMatrix<f64>,
    vxa: DMatrix<f64>,
    vxb: DMatrix<f64>,
    t_mn: DMatrix<f64>,
    vx: DVector<f64>,
    qu: DVector<f64>,
    w: DVector<f64>,
    dm: DVector<f64>,
    dm_next: DVector<f64>,
    du: DVector<f64>,
    /// The mean's linear response to a step along the line search (`δm_k`, scaled by `α` where
    /// used), and scratch for the feedback.
    lin_dm: DVector<f64>,
    lin_next: DVector<f64>,
    dev: DVector<f64>,
}

impl Precond {
    pub(super) fn new(n: usize, m: usize, horizon: usize) -> Self {
        let z = |r, c| DMatrix::zeros(r, c);
        Precond {
            knots: (0..horizon)
                .map(|_| PrecondKnot {
                    a: z(n, n),
                    b: z(n, m),
                    quu: z(m, m),
                    qux: z(m, n),
                    gain: z(m, n),
                    factor: SmallCholesky::EMPTY,
                    free: [0; MAX_QP],
                    nf: 0,
                    kff: DVector::zeros(m),
                })
                .collect(),
            vxx: z(n, n),
            qxx: z(n, n),
            vxa: z(n, n),
            vxb: z(n, m),
            t_mn: z(m, n),
            vx: DVector::zeros(n),
            qu: DVector::zeros(m),
            w: DVector::zeros(m),
            dm: DVector::zeros(n),
            dm_next: DVector::zeros(n),
            du: DVector::zeros(m),
            lin_dm: DVector::zeros(n),
            lin_next: DVector::zeros(n),
            dev: DVector::zeros(n),
        }
    }

    /// Starts the mean's linear response `δm₀ = 0` for [`Precond::feedback`].
    pub(super) fn reset_linear(&mut self) {
        zero(&mut self.lin_dm);
    }

    /// `u += K_k (m' − m − α δm_k)`: the gains' correction of the mean's deviation from its
    /// linear prediction at knot `k`.
    pub(super) fn feedback(
        &mut self,
        k: usize,
        m_new: nalgebra::DVectorView<f64>,
        m_old: nalgebra::DVectorView<f64>,
        alpha: f64,
        u: &mut DVector<f64>,
    ) {
        self.dev.copy_from(&m_new);
        self.dev -= &m_old;
        self.dev.axpy(-alpha, &self.lin_dm, 1.0);
        u.gemv(1.0, &self.knots[k].gain, &self.dev, 1.0);
    }

    /// `δm_{k+1} = A_k δm_k + B_k d_k`.
    pub(super) fn advance_linear(&mut self, k: usize, d: &[f64]) {
        let pk = &self.knots[k];
        self.lin_next.gemv(1.0, &pk.a, &self.lin_dm, 0.0);
        for (j, v) in d.iter().enumerate() {
            self.lin_next.axpy(*v, &pk.b.column(j), 1.0);
        }
        std::mem::swap(&mut self.lin_dm, &mut self.lin_next);
    }

    /// `out = M_FF⁻¹ r` on the free controls (0 on the others): the LQ problem's backward pass
    /// with `r` as the controls' linear term, then its forward pass from `δm₀ = 0`, negated.
    pub(super) fn apply(&mut self, r: &[f64], out: &mut [f64]) {
        let m = self.qu.len();
        zero(&mut self.vx);
        for (k, pk) in self.knots.iter_mut().enumerate().rev() {
            // q_u = r_k + Bᵀ v_x, q_x = Aᵀ v_x.
            self.qu.copy_from_slice(&r[k * m..(k + 1) * m]);
            self.qu.gemv_tr(1.0, &pk.b, &self.vx, 1.0);
            let mut rhs = [0.0; MAX_QP];
            for (i, &j) in pk.free[..pk.nf].iter().enumerate() {
                rhs[i] = -self.qu[j];
            }
            pk.factor.solve(&mut rhs[..pk.nf]);
            zero(&mut pk.kff);
            for (i, &j) in pk.free[..pk.nf].iter().enumerate() {
                pk.kff[j] = rhs[i];
            }
            // v_x = Aᵀ v_x + Kᵀ (Q_uu k + q_u) + Q_uxᵀ k.
            self.w.copy_from(&self.qu);
            self.w.gemv(1.0, &pk.quu, &pk.kff, 1.0);
            self.dm.gemv_tr(1.0, &pk.a, &self.vx, 0.0);
            self.dm.gemv_tr(1.0, &pk.gain, &self.w, 1.0);
            self.dm.gemv_tr(1.0, &pk.qux, &pk.kff, 1.0);
            self.vx.copy_from(&self.dm);
        }
        zero(&mut self.dm);
        for (k, pk) in self.knots.iter().enumerate() {
            self.du.copy_from(&pk.kff);
            self.du.gemv(1.0, &pk.gain, &self.dm, 1.0);
            for j in 0..m {
                out[k * m + j] = -self.du[j];
            }
            self.dm_next.gemv(1.0, &pk.a, &self.dm, 0.0);
            self.dm_next.gemv(1.0, &pk.b, &self.du, 1.0);
            std::mem::swap(&mut self.dm, &mut self.dm_next);
        }
    }
}

impl SoocFastSolver {
    /// Factorises the surrogate's `M` restricted to the controls `free` marks (`k m + j`), with
    /// each free control's `Q_uu` diagonal raised by `mu` times itself (a diagonal added to
    /// `M`: the factorisation stays that of a fixed symmetric matrix). Each control's model
    /// curvature (its unregularised `Q_uu` diagonal) goes to `curvature`. False if a free block
    /// is not positive definite. Needs [`Self::model`] at the current controls.
    pub(super) fn factor(&mut self, free: &[bool], mu: f64) -> bool {
        let (n, m, h) = (self.n, self.nu, self.horizon);
        let pc = &mut self.precond;
        pc.vxx.copy_from(&self.terminal.lxx.view((0, 0), (n, n)));
        for k in (0..h).rev() {
            let kn = &self.knots[k];
            let lin = kn.e.flow_sensitivity().lin;
            let d = &kn.d;
            let pk = &mut pc.knots[k];
            pk.a.copy_from(&lin.a);
            pk.b.copy_from(&lin.b);
            multiply(&mut pc.vxa, &pc.vxx, &lin.a, false);
            multiply(&mut pc.vxb, &pc.vxx, &lin.b, false);
            pc.qxx.copy_from(&d.lxx.view((0, 0), (n, n)));
            pc.qxx += &kn.g.view((0, 0), (n, n));
            pc.qxx.gemm_tr(1.0, &lin.a, &pc.vxa, 1.0);
            pk.quu.copy_from(&d.luu);
            pk.quu += &kn.g.view((n, n), (m, m));
            pk.quu.gemm_tr(1.0, &lin.b, &pc.vxb, 1.0);
            pk.qux.copy_from(&d.lux.view((0, 0), (m, n)));
            pk.qux += &kn.g.view((n, 0), (m, n));
            pk.qux.gemm_tr(1.0, &lin.b, &pc.vxa, 1.0);
            for i in 0..m {
                for j in 0..i {
                    let v = 0.5 * (pk.quu[(i, j)] + pk.quu[(j, i)]);
                    pk.quu[(i, j)] = v;
                    pk.quu[(j, i)] = v;
                }
                self.curvature[k][i] = pk.quu[(i, i)];
                pk.quu[(i, i)] += mu * pk.quu[(i, i)].abs().max(1e-12);
            }
            pk.nf = 0;
            for j in 0..m {
                if free[k * m + j] {
                    pk.free[pk.nf] = j;
                    pk.nf += 1;
                }
            }
            let quu = &pk.quu;
            if !pk.factor.factorize(|i, j| quu[(i, j)], &pk.free[..pk.nf]) {
                return false;
            }
            // K_F = −Q_uu,FF⁻¹ Q_ux,F; clamped rows 0.
            zero(&mut pk.gain);
            for c in 0..n {
                let mut col = [0.0; MAX_QP];
                for (i, &j) in pk.free[..pk.nf].iter().enumerate() {
                    col[i] = -pk.qux[(j, c)];
                }
                pk.factor.solve(&mut col[..pk.nf]);
                for (i, &j) in pk.free[..pk.nf].iter().enumerate() {
                    pk.gain[(j, c)] = col[i];
                }
            }
            // V_xx = Q_xx + Kᵀ (Q_uu K + Q_ux) + Q_uxᵀ K, symmetrised.
            pc.t_mn.copy_from(&pk.qux);
            multiply(&mut pc.t_mn, &pk.quu, &pk.gain, true);
            pc.vxx.copy_from(&pc.qxx);
            pc.vxx.gemm_tr(1.0, &pk.gain, &pc.t_mn, 1.0);
            pc.vxx.gemm_tr(1.0, &pk.qux, &pk.gain, 1.0);
            for i in 0..n {
                for j in 0..i {
                    let v = 0.5 * (pc.vxx[(i, j)] + pc.vxx[(j, i)]);
                    pc.vxx[(i, j)] = v;
                    pc.vxx[(j, i)] = v;
                }
            }
        }
        true
    }
}
