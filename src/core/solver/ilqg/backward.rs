//! The backward pass of ILQG (Todorov & Li 2005, Eq. 4–6 of the Q-function with the noise terms):
//! per knot from the last, the Q-function, the box-limited policy and the value update.

use super::knot::{Knot, Value};
use super::policy::policy;
use super::*;
use crate::core::dense::{copy, transpose};
use crate::core::solver::sparse::ColumnProducts;

/// Whether the backward pass reads a knot's Jacobians in place, on the stack ([`super::knot`]),
/// rather than by the nonzero pattern of `Trajectory::sparse` (which the linearisation then need
/// not build): the sizes of the paper's plants (the single joint with torque or torque and
/// stiffness, the two-link arm with either, the VSA arm). [`Ilqg::backward_pass`] must have an
/// arm for each.
pub(super) fn reads_in_place(nx: usize, nu: usize) -> bool {
    matches!((nx, nu), (2, 1) | (2, 2) | (4, 2) | (4, 4) | (8, 4))
}

/// Scratch matrices of the backward pass.
pub(super) struct Backward {
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

impl Ilqg {
    /// Backward passes with μ raised until every `Q_uu` is positive definite; `None` when μ
    /// passes its limit first.
    pub(super) fn regularized_backward_pass(
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

    /// Mean magnitude of the diagonal of the value Hessian at the first knot of the last backward
    /// pass: the scale against which the regularisation μ is large or small.
    pub(super) fn value_scale(&self) -> f64 {
        let s = &self.bw.s_mat;
        let n = s.nrows().max(1);
        (0..s.nrows()).map(|i| s[(i, i)].abs()).sum::<f64>() / n as f64
    }

    /// One backward pass (Todorov & Li 2005) at the nominal with regularisation `mu`: per knot,
    /// from the last, the Q-function, the policy from the (box) QP, the value update. `None` when a
    /// `Q_uu` is not positive definite. The paper's plant sizes run on the stack
    /// ([`super::knot`]), the others by the Jacobians' nonzero patterns: the same numbers.
    pub(super) fn backward_pass(
        &mut self,
        problem: &Problem,
        mu: f64,
        stochastic: bool,
    ) -> Option<BackwardPass> {
        match (self.dims.0, self.dims.1) {
            (2, 1) => self.backward_sized::<2, 1>(problem, mu, stochastic),
            (2, 2) => self.backward_sized::<2, 2>(problem, mu, stochastic),
            (4, 2) => self.backward_sized::<4, 2>(problem, mu, stochastic),
            (4, 4) => self.backward_sized::<4, 4>(problem, mu, stochastic),
            (8, 4) => self.backward_sized::<8, 4>(problem, mu, stochastic),
            (nx, nu) => {
                // The pattern is not built for the sizes read in place: reading it there would
                // see zero Jacobians. A size added to one list must be added to the other.
                assert!(!reads_in_place(nx, nu), "{nx}x{nu} is read in place");
                self.backward_sparse(problem, mu, stochastic)
            }
        }
    }

    /// [`Ilqg::backward_fixed`] in AVX2's 256-bit registers where [`crate::core::wide`] allows
    /// it (the same numbers to the bit), else in the portable build's 128-bit ones.
    fn backward_sized<const NX: usize, const NU: usize>(
        &mut self,
        problem: &Problem,
        mu: f64,
        stochastic: bool,
    ) -> Option<BackwardPass> {
        #[cfg(target_arch = "x86_64")]
        if crate::core::wide::enabled() {
            // SAFETY: `enabled` is true only where the CPU reported AVX2.
            return unsafe { self.backward_avx2::<NX, NU>(problem, mu, stochastic) };
        }
        self.backward_fixed::<NX, NU>(problem, mu, stochastic)
    }

    /// [`Ilqg::backward_fixed`] compiled for AVX2 (see [`crate::core::wide`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn backward_avx2<const NX: usize, const NU: usize>(
        &mut self,
        problem: &Problem,
        mu: f64,
        stochastic: bool,
    ) -> Option<BackwardPass> {
        self.backward_fixed::<NX, NU>(problem, mu, stochastic)
    }

    /// [`Ilqg::backward_pass`] on the stack for an `NX`-state, `NU`-control plant. The value
    /// function stays in registers and stack arrays from knot to knot; `bw.s_mat` and `bw.s_vec`
    /// receive it at the end, where the dynamic path leaves them (for [`Ilqg::value_scale`]).
    /// Inlined into its two callers, so that each compiles it (and the knot's operations) for
    /// its own instruction set.
    #[inline(always)]
    fn backward_fixed<const NX: usize, const NU: usize>(
        &mut self,
        problem: &Problem,
        mu: f64,
        stochastic: bool,
    ) -> Option<BackwardPass> {
        let horizon = self.dims.3;
        let traj = &self.nominal;
        let mut v = Value::<NX>::terminal(&traj.derivs[horizon]);
        let mut pass = BackwardPass {
            s0: traj.terminal,
            dv1: 0.0,
            dv2: 0.0,
        };
        let mut knot = Knot::<NX, NU>::EMPTY;
        let mut failed = false;
        for k in (0..horizon).rev() {
            if stochastic {
                // Only the stochastic merit reads them.
                self.value_hessians[k]
                    .as_mut_slice()
                    .copy_from_slice(v.s_mat.as_flattened());
            }
            let running = traj.running[k];
            let q0 =
                knot.expand(&v, (&traj.lin[k], &traj.derivs[k]), running, stochastic, mu) + pass.s0;
            let (l, gain) = (self.ff[k].as_mut_slice(), self.gains[k].as_mut_slice());
            if !knot.policy(&problem.bounds, traj.u[k].as_slice(), l, gain) {
                failed = true;
                break;
            }
            let (lqu, lquul) = knot.value_update(l, gain, &mut v);
            pass.s0 = q0 + lqu + 0.5 * lquul;
            pass.dv1 += lqu;
            pass.dv2 += 0.5 * lquul;
        }
        self.bw
            .s_mat
            .as_mut_slice()
            .copy_from_slice(v.s_mat.as_flattened());
        self.bw.s_vec.as_mut_slice().copy_from_slice(&v.s_vec);
        (!failed).then_some(pass)
    }

    /// [`Ilqg::backward_pass`] by the Jacobians' nonzero patterns (`Trajectory::sparse`).
    fn backward_sparse(
        &mut self,
        problem: &Problem,
        mu: f64,
        stochastic: bool,
    ) -> Option<BackwardPass> {
        let horizon = self.dims.3;
        let bw = &mut self.bw;
        let traj = &self.nominal;
        let term = &traj.derivs[horizon];
        // The value Hessian `S_{k+1}` the knot reads: in a stochastic pass the merit's
        // `value_hessians[k]`, which the value update of knot k + 1 writes (no copy of a
        // 42×42 matrix per knot on the delayed plant); otherwise `s_mat`, updated in place.
        // `S_0` ends in `s_mat` either way ([`Ilqg::value_scale`]).
        let mut s_mat = std::mem::take(&mut bw.s_mat);
        let chained = stochastic && horizon > 0;
        copy(
            &term.lxx,
            if chained {
                &mut self.value_hessians[horizon - 1]
            } else {
                &mut s_mat
            },
        );
        copy(&term.lx, &mut bw.s_vec);
        let mut pass = BackwardPass {
            s0: traj.terminal,
            dv1: 0.0,
            dv2: 0.0,
        };
        let mut failed = false;
        for k in (0..horizon).rev() {
            let running = traj.running[k];
            let (lin, sp) = (&traj.lin[k], &traj.sparse[k]);
            let s_next = if chained {
                &self.value_hessians[k]
            } else {
                &s_mat
            };
            let q0 =
                bw.q_function(s_next, (lin, &traj.derivs[k]), sp, running, stochastic) + pass.s0;
            bw.regularize(&sp.b, lin, mu);
            if !policy::<MAX_QP>(
                bw.quu_reg.as_slice(),
                bw.qu.as_slice(),
                bw.qux_reg.as_slice(),
                &problem.bounds,
                traj.u[k].as_slice(),
                self.ff[k].as_mut_slice(),
                self.gains[k].as_mut_slice(),
            ) {
                failed = true;
                break;
            }
            let s_here = if chained && k > 0 {
                &mut self.value_hessians[k - 1]
            } else {
                &mut s_mat
            };
            let (lqu, lquul) = bw.value_update(&self.ff[k], &self.gains[k], s_here);
            pass.s0 = q0 + lqu + 0.5 * lquul;
            pass.dv1 += lqu;
            pass.dv2 += 0.5 * lquul;
        }
        bw.s_mat = s_mat;
        (!failed).then_some(pass)
    }
}

/// `y = S c` taking `c` by its nonzeros: the noise columns live in the plant's rows (those of
/// the delayed plant's commands in flight are zero), so on the 42-state delayed single joint
/// this is 2 of 42 columns of `S`. The columns are added in ascending order, each term
/// `s_ij c_j` to `y_i` as nalgebra's `gemv` adds every column; a skipped term would add exactly 0,
/// so `y` is `gemv`'s to the bit (up to the sign of an entry that ends at zero).
fn mul_nonzeros(s: &DMatrix<f64>, c: &[f64], y: &mut DVector<f64>) {
    let n = s.nrows();
    let (sd, yd) = (s.as_slice(), y.as_mut_slice());
    yd.fill(0.0);
    for (j, &cj) in c.iter().enumerate() {
        if cj != 0.0 {
            for (yi, &sij) in yd.iter_mut().zip(&sd[j * n..(j + 1) * n]) {
                *yi += sij * cj;
            }
        }
    }
}

impl Backward {
    pub(super) fn new(nx: usize, nu: usize) -> Self {
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

    /// The Q-function of a knot (Todorov & Li 2005) from the value `(S, s)` of the next knot, into
    /// `qx, qu, qxx, quu, qux`; returns its constant term `running + ½ Σ c_iᵀ S c_i` (without
    /// `s₀`). The products take A, B, Cx, Cu by their nonzeros `sp` (see `sparse`): n·nnz, not n³.
    fn q_function(
        &mut self,
        s: &DMatrix<f64>,
        (lin, d): (&Linearization, &CostDerivatives),
        sp: &SparseLinearization,
        running: f64,
        stochastic: bool,
    ) -> f64 {
        let (a, b) = (&sp.a, &sp.b);
        let mut q0 = running;
        copy(&d.lx, &mut self.qx);
        a.tr_mul_vec_add(1.0, self.s_vec.as_slice(), self.qx.as_mut_slice());
        copy(&d.lu, &mut self.qu);
        b.tr_mul_vec_add(1.0, self.s_vec.as_slice(), self.qu.as_mut_slice());
        a.right_mul(s, &mut self.sa);
        b.right_mul(s, &mut self.sb);
        transpose(&self.sa, &mut self.sat);
        a.right_mul_onto(&d.lxx, &self.sat, &mut self.qxx);
        copy(&d.luu, &mut self.quu);
        b.tr_mul_add(1.0, &self.sb, &mut self.quu);
        copy(&d.lux, &mut self.qux);
        b.tr_mul_add(1.0, &self.sa, &mut self.qux);
        if stochastic && lin.noise != NoiseKind::None {
            for i in 0..lin.c.ncols() {
                mul_nonzeros(s, lin.c.column(i).as_slice(), &mut self.sc);
                q0 += 0.5 * lin.c.column(i).dot(&self.sc);
                if lin.noise == NoiseKind::Dependent {
                    let (cx, cu) = (&sp.cx[i], &sp.cu[i]);
                    cx.tr_mul_vec_add(1.0, self.sc.as_slice(), self.qx.as_mut_slice());
                    cu.tr_mul_vec_add(1.0, self.sc.as_slice(), self.qu.as_mut_slice());
                    cx.right_mul(s, &mut self.scx);
                    cu.right_mul(s, &mut self.scu);
                    // `Cxᵀ S Cx` from the rows of `S Cx` (no transpose of it).
                    cx.tr_right_mul_add(&self.scx, &mut self.qxx);
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
    fn regularize(&mut self, b: impl ColumnProducts, lin: &Linearization, mu: f64) {
        copy(&self.quu, &mut self.quu_reg);
        copy(&self.qux, &mut self.qux_reg);
        if mu > 0.0 {
            b.tr_mul_add(mu, &lin.b, &mut self.quu_reg);
            b.tr_mul_add(mu, &lin.a, &mut self.qux_reg);
            for j in 0..self.quu_reg.nrows() {
                // A trace of control-space damping for controls that do not move the state.
                self.quu_reg[(j, j)] += mu * 1e-6;
            }
        }
    }

    /// Value function update (Tassa 2012 form, valid with regularisation and clamping):
    /// `s = Q_x + Lᵀ Q_uu l + Lᵀ Q_u + Q_uxᵀ l`, `S = Q_xx + Lᵀ Q_uu L + Lᵀ Q_ux + Q_uxᵀ L`.
    /// Into `s_mat` (the value Hessian `S`); returns `(lᵀ Q_u, lᵀ Q_uu l)` for `s_0` and the
    /// expected improvement.
    fn value_update(
        &mut self,
        l: &DVector<f64>,
        gain: &DMatrix<f64>,
        s_mat: &mut DMatrix<f64>,
    ) -> (f64, f64) {
        let nu = l.len();
        let (lqu, lquul) = self.value_terms_dynamic(l, gain);
        // S = Q_xx + Lᵀ (Q_uu L + Q_ux) + Q_uxᵀ L as 2m rank-one updates, each an axpy on
        // contiguous columns of the transposed thin factors (nalgebra's transposed products
        // are plain dot loops). The first update reads `Q_xx` where the others read `S`: the
        // same sums as a copy of `Q_xx` followed by every update, without that pass.
        transpose(gain, &mut self.lt);
        transpose(&self.qux, &mut self.xt);
        let n = s_mat.nrows();
        let (gd, td) = (gain.as_slice(), self.t_mn.as_slice());
        let (ltd, xtd) = (self.lt.as_slice(), self.xt.as_slice());
        let qd = self.qxx.as_slice();
        let sd = s_mat.as_mut_slice();
        for j in 0..n {
            let col = &mut sd[j * n..(j + 1) * n];
            let q = &qd[j * n..(j + 1) * n];
            for r in 0..nu {
                let (t, g) = (td[j * nu + r], gd[j * nu + r]);
                let (lr, xr) = (&ltd[r * n..(r + 1) * n], &xtd[r * n..(r + 1) * n]);
                if r == 0 {
                    for (((s, q), l), x) in col.iter_mut().zip(q).zip(lr).zip(xr) {
                        *s = q + (l * t + x * g);
                    }
                } else {
                    for ((s, l), x) in col.iter_mut().zip(lr).zip(xr) {
                        *s += l * t + x * g;
                    }
                }
            }
            if nu == 0 {
                col.copy_from_slice(q);
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

impl Backward {
    /// The products of the value update before its rank-one part, by nalgebra: `t_m = Q_uu l +
    /// Q_u`, `s = Q_x + Lᵀ t_m + Q_uxᵀ l`, `t_mn = Q_uu L + Q_ux`; returns `(lᵀ Q_u, lᵀ Q_uu l)`.
    fn value_terms_dynamic(&mut self, l: &DVector<f64>, gain: &DMatrix<f64>) -> (f64, f64) {
        self.t_m.gemv(1.0, &self.quu, l, 0.0); // Q_uu l
        let lqu = l.dot(&self.qu);
        let lquul = l.dot(&self.t_m);
        self.t_m += &self.qu; // Q_uu l + Q_u
        copy(&self.qx, &mut self.s_vec);
        self.s_vec.gemv_tr(1.0, gain, &self.t_m, 1.0);
        self.s_vec.gemv_tr(1.0, &self.qux, l, 1.0);
        copy(&self.qux, &mut self.t_mn);
        self.t_mn.gemm(1.0, &self.quu, gain, 1.0); // Q_uu L + Q_ux
        (lqu, lquul)
    }
}

#[cfg(test)]
mod tests;
