//! The backward pass of ILQG (Todorov & Li 2005, Eq. 4–6 of the Q-function with the noise terms):
//! per knot from the last, the Q-function, the box-limited policy and the value update.

use super::knot::{Knot, Value};
use super::policy::policy;
use super::*;
use crate::dense::{copy, symmetrize, transpose};
use crate::solver::sparse::ColumnProducts;
use std::mem::take;

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
    /// The value Hessian a pass that updates `s_mat` in place writes before it takes its
    /// place (the update reads `S_{k+1}` column by column as it writes `S_k`).
    spare: DMatrix<f64>,
    /// `S_{k+1}ᵀ` when `S_{k+1}` is not symmetric to the bit (a cost's terminal Hessian may
    /// not be): its columns are the rows of `S_{k+1}` that the products read.
    s_rows: DMatrix<f64>,
    sa: DMatrix<f64>,
    /// `(S A)ᵀ = Aᵀ S` (S is symmetric), so that `Aᵀ S A` is a product by A's columns.
    sat: DMatrix<f64>,
    /// `Lᵀ` and `Q_uxᵀ` (n×m): the value update by contiguous columns.
    lt: DMatrix<f64>,
    xt: DMatrix<f64>,
    sb: DMatrix<f64>,
    scu: DMatrix<f64>,
    sc: DVector<f64>,
    qx: DVector<f64>,
    qu: DVector<f64>,
    /// One column of `Q_xx` ([`Backward::q_column`]) and one row of a product `S M`.
    qcol: DVector<f64>,
    row: DVector<f64>,
    /// Rows of `S Cx` ([`tr_mul_product_add`](crate::solver::sparse::SparseColumns::tr_mul_product_add)).
    rows: Vec<f64>,
    quu: DMatrix<f64>,
    qux: DMatrix<f64>,
    quu_reg: DMatrix<f64>,
    qux_reg: DMatrix<f64>,
    t_mn: DMatrix<f64>,
    t_m: DVector<f64>,
}

/// The next knot's value Hessian `S_{k+1}` as the sparse backward pass reads it: `s` by its
/// columns, and `rows`, whose column `i` is row `i` of `s` (`s` itself, `S` being symmetric,
/// but for a terminal cost Hessian that is not symmetric to the bit).
#[derive(Clone, Copy)]
struct Next<'a> {
    s: &'a DMatrix<f64>,
    rows: &'a DMatrix<f64>,
}

/// One knot's linearisation (dense and by its nonzeros) and cost derivatives, with the columns
/// of `l_xx` that can be nonzero.
#[derive(Clone, Copy)]
struct KnotInputs<'a> {
    lin: &'a Linearization,
    d: &'a CostDerivatives,
    sp: &'a SparseLinearization,
    hessian: &'a std::ops::Range<usize>,
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

    /// [`Ilqg::backward_fixed`] in AVX2's 256-bit registers where [`crate::wide`] allows
    /// it (the same numbers to the bit), else in the portable build's 128-bit ones.
    fn backward_sized<const NX: usize, const NU: usize>(
        &mut self,
        problem: &Problem,
        mu: f64,
        stochastic: bool,
    ) -> Option<BackwardPass> {
        #[cfg(target_arch = "x86_64")]
        if crate::wide::enabled() {
            // SAFETY: `enabled` is true only where the CPU reported AVX2.
            return unsafe { self.backward_avx2::<NX, NU>(problem, mu, stochastic) };
        }
        self.backward_fixed::<NX, NU>(problem, mu, stochastic)
    }

    /// [`Ilqg::backward_fixed`] compiled for AVX2 (see [`crate::wide`]).
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
        // The value Hessian `S_{k+1}` the knot reads is `s_mat`, and `S_k` goes to `spare`,
        // which then takes its place; `S_0` ends in `s_mat` ([`Ilqg::value_scale`]). A
        // stochastic pass keeps each `S_{k+1}` for the merit in the rows where the noise acts
        // only: the delayed plant's 2 of 42 (a whole 42×42 matrix per knot would be a stream of
        // 2 MB written per pass).
        let mut s_mat = take(&mut bw.s_mat);
        let noise = traj.noise_rows();
        copy(&term.lxx, &mut s_mat);
        if stochastic && horizon > 0 {
            keep_block(&s_mat, &noise, &mut self.value_hessians[horizon - 1]);
        }
        copy(&term.lx, &mut bw.s_vec);
        let mut pass = BackwardPass {
            s0: traj.terminal,
            dv1: 0.0,
            dv2: 0.0,
        };
        let mut failed = false;
        let (mut spare, mut s_rows) = (take(&mut bw.spare), take(&mut bw.s_rows));
        for k in (0..horizon).rev() {
            let running = traj.running[k];
            let (lin, sp) = (&traj.lin[k], &traj.sparse[k]);
            // The update reads `S_{k+1}` while it writes `S_k`.
            let (s_next, s_here) = (&s_mat, &mut spare);
            // Every later `S` is symmetric to the bit (the value update makes it so); a
            // terminal Hessian need not be.
            let transposed = k + 1 == horizon && !symmetric(s_next);
            if transposed {
                transpose(s_next, &mut s_rows);
            }
            let next = Next {
                s: s_next,
                rows: if transposed { &s_rows } else { s_next },
            };
            let knot = KnotInputs {
                lin,
                d: &traj.derivs[k],
                sp,
                hessian: &traj.hessian,
            };
            let q0 = bw.q_function(next, knot, running, stochastic) + pass.s0;
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
            let (lqu, lquul) = bw.value_update(
                (next, knot, stochastic),
                &self.ff[k],
                &self.gains[k],
                s_here,
            );
            std::mem::swap(&mut s_mat, &mut spare);
            if stochastic && k > 0 {
                keep_block(&s_mat, &noise, &mut self.value_hessians[k - 1]);
            }
            pass.s0 = q0 + lqu + 0.5 * lquul;
            pass.dv1 += lqu;
            pass.dv2 += 0.5 * lquul;
        }
        (bw.s_mat, bw.spare, bw.s_rows) = (s_mat, spare, s_rows);
        (!failed).then_some(pass)
    }
}

/// Copies the rows and columns `rows` of `s` into the same entries of `kept`.
fn keep_block(s: &DMatrix<f64>, rows: &std::ops::Range<usize>, kept: &mut DMatrix<f64>) {
    let n = s.nrows();
    let (sd, kd) = (s.as_slice(), kept.as_mut_slice());
    for j in rows.clone() {
        let r = j * n + rows.start..j * n + rows.end;
        kd[r.clone()].copy_from_slice(&sd[r]);
    }
}

/// Whether `m` equals its transpose to the bit.
fn symmetric(m: &DMatrix<f64>) -> bool {
    let n = m.nrows();
    (0..n).all(|j| (j + 1..n).all(|i| m[(i, j)].to_bits() == m[(j, i)].to_bits()))
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
            spare: DMatrix::zeros(nx, nx),
            s_rows: DMatrix::zeros(nx, nx),
            sa: DMatrix::zeros(nx, nx),
            sat: DMatrix::zeros(nx, nx),
            lt: DMatrix::zeros(nx, nu),
            xt: DMatrix::zeros(nx, nu),
            sb: DMatrix::zeros(nx, nu),
            scu: DMatrix::zeros(nx, nu),
            sc: DVector::zeros(nx),
            qx: DVector::zeros(nx),
            qu: DVector::zeros(nu),
            qcol: DVector::zeros(nx),
            row: DVector::zeros(nx),
            rows: Vec::with_capacity(nx * nx),
            quu: DMatrix::zeros(nu, nu),
            qux: DMatrix::zeros(nu, nx),
            quu_reg: DMatrix::zeros(nu, nu),
            qux_reg: DMatrix::zeros(nu, nx),
            t_mn: DMatrix::zeros(nu, nx),
            t_m: DVector::zeros(nu),
        }
    }

    /// The Q-function of a knot (Todorov & Li 2005) from the value `(S, s)` of the next knot, into
    /// `qx, qu, quu, qux`; returns its constant term `running + ½ Σ c_iᵀ S c_i` (without `s₀`).
    /// The products take A, B, Cx, Cu by their nonzeros `sp` (see `sparse`): n·nnz, not n³.
    /// `Q_xx`, the one `n × n` block, is formed column by column in [`Backward::value_update`],
    /// which needs it only one column at a time: here `S A` is formed and transposed for it,
    /// and `S Cx` is read only in the rows that `Cu` takes
    /// ([`tr_mul_product_add`](crate::solver::sparse::SparseColumns::tr_mul_product_add)).
    fn q_function(&mut self, next: Next, knot: KnotInputs, running: f64, stochastic: bool) -> f64 {
        let KnotInputs { lin, d, sp, .. } = knot;
        let (a, b) = (&sp.a, &sp.b);
        let s = next.s;
        let mut q0 = running;
        copy(&d.lx, &mut self.qx);
        a.tr_mul_vec_add(1.0, self.s_vec.as_slice(), self.qx.as_mut_slice());
        copy(&d.lu, &mut self.qu);
        b.tr_mul_vec_add(1.0, self.s_vec.as_slice(), self.qu.as_mut_slice());
        a.right_mul(s, &mut self.sa);
        b.right_mul(s, &mut self.sb);
        transpose(&self.sa, &mut self.sat);
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
                    if cu.nnz() > 0 {
                        // Else `S Cu` is zero and adds nothing (the delayed plant's `Cu_i`).
                        cu.right_mul(s, &mut self.scu);
                        cu.tr_mul_add(1.0, &self.scu, &mut self.quu);
                    }
                    cu.tr_mul_product_add(1.0, next.rows, cx, &mut self.rows, &mut self.qux);
                }
            }
        }
        q0
    }

    /// Column `j` of `Q_xx = l_xx + Aᵀ S A + Σ Cx_iᵀ S Cx_i` into `qcol`, to the bit what the
    /// whole matrix `l_xx + (S A)ᵀ A` plus each channel's `Cx_iᵀ (S Cx_i)` gave: the columns of
    /// `(S A)ᵀ` that `A`'s column `j` takes (one on the 42-state delayed plant's shift columns),
    /// then the rows of `S Cx_i` that `Cx_i`'s column `j` takes (none outside the plant).
    fn q_column(&mut self, next: Next, knot: KnotInputs, stochastic: bool, j: usize) {
        let KnotInputs {
            lin,
            d,
            sp,
            hessian,
        } = knot;
        let n = self.qcol.len();
        // A column of `l_xx` outside the cost's support is +0 (not read: see
        // `Cost::hessian_support`), and `0 + x` is what adding it gives, to the bit.
        let base = hessian
            .contains(&j)
            .then(|| &d.lxx.as_slice()[j * n..(j + 1) * n]);
        let (q, row) = (self.qcol.as_mut_slice(), self.row.as_mut_slice());
        let (rows, vals) = sp.a.column(j);
        if rows.is_empty() {
            match base {
                Some(base) => q.copy_from_slice(base),
                None => q.fill(0.0),
            }
        }
        let sat = self.sat.as_slice();
        for (t, (&i, &a)) in rows.iter().zip(vals).enumerate() {
            let si = &sat[i * n..(i + 1) * n];
            if t == 0 {
                match base {
                    Some(base) => {
                        for ((q, b), r) in q.iter_mut().zip(base).zip(si) {
                            *q = b + a * r;
                        }
                    }
                    None => {
                        for (q, r) in q.iter_mut().zip(si) {
                            *q = 0.0 + a * r;
                        }
                    }
                }
            } else {
                for (q, r) in q.iter_mut().zip(si) {
                    *q += a * r;
                }
            }
        }
        if stochastic && lin.noise == NoiseKind::Dependent {
            for cx in &sp.cx {
                let (rows, vals) = cx.column(j);
                for (&i, &a) in rows.iter().zip(vals) {
                    cx.product_row(next.rows, i, row);
                    for (q, r) in q.iter_mut().zip(&*row) {
                        *q += a * r;
                    }
                }
            }
        }
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
    /// Into `s_mat` (the value Hessian `S`, not `next`'s); returns `(lᵀ Q_u, lᵀ Q_uu l)` for
    /// `s_0` and the expected improvement.
    fn value_update(
        &mut self,
        (next, knot, stochastic): (Next, KnotInputs, bool),
        l: &DVector<f64>,
        gain: &DMatrix<f64>,
        s_mat: &mut DMatrix<f64>,
    ) -> (f64, f64) {
        let nu = l.len();
        let (lqu, lquul) = self.value_terms_dynamic(l, gain);
        // S = Q_xx + Lᵀ (Q_uu L + Q_ux) + Q_uxᵀ L as 2m rank-one updates, each an axpy on
        // contiguous columns of the transposed thin factors (nalgebra's transposed products
        // are plain dot loops). Each column of `Q_xx` is formed just before its column of `S`
        // (in L1, where a whole `Q_xx` would be a pass over memory of its own), and the first
        // update reads it where the others read `S`.
        transpose(gain, &mut self.lt);
        transpose(&self.qux, &mut self.xt);
        let n = s_mat.nrows();
        for j in 0..n {
            self.q_column(next, knot, stochastic, j);
            let (gd, td) = (gain.as_slice(), self.t_mn.as_slice());
            let (ltd, xtd) = (self.lt.as_slice(), self.xt.as_slice());
            let q = self.qcol.as_slice();
            let col = &mut s_mat.as_mut_slice()[j * n..(j + 1) * n];
            if nu == 2 {
                // Both rank-one terms in one pass over the column (two controls: the single
                // joint's torque and stiffness), each entry's operations as two passes do them.
                let (t, g) = ((td[j * 2], td[j * 2 + 1]), (gd[j * 2], gd[j * 2 + 1]));
                let (l0, l1) = ltd.split_at(n);
                let (x0, x1) = xtd.split_at(n);
                let terms = l0.iter().zip(l1).zip(x0.iter().zip(x1));
                for ((s, q), ((l0, l1), (x0, x1))) in col.iter_mut().zip(q).zip(terms) {
                    *s = q + (l0 * t.0 + x0 * g.0);
                    *s += l1 * t.1 + x1 * g.1;
                }
                continue;
            }
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
        symmetrize(s_mat);
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
