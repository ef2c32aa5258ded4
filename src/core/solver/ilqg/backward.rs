//! The backward pass of ILQG (Todorov & Li 2005, Eq. 4–6 of the Q-function with the noise terms):
//! per knot from the last, the Q-function, the box-limited policy and the value update.

use super::*;
use crate::core::dense::{copy, transpose, zero};
use crate::core::solver::sparse::{ColumnProducts, SmallDense};

/// Whether the backward pass reads a knot's Jacobians in place, by fixed-size loops
/// ([`SmallDense`]), rather than by the nonzero pattern of `Trajectory::sparse` (which the
/// linearisation then need not build): the sizes of the paper's plants (the single joint with
/// torque or torque and stiffness, the two-link arm with either, the VSA arm).
/// [`Backward::q_regularized`] must have an arm for each.
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
    /// `Q_uu` is not positive definite.
    pub(super) fn backward_pass(
        &mut self,
        problem: &Problem,
        mu: f64,
        stochastic: bool,
    ) -> Option<BackwardPass> {
        let horizon = self.dims.3;
        let bw = &mut self.bw;
        let traj = &self.nominal;
        let term = &traj.derivs[horizon];
        copy(&term.lxx, &mut bw.s_mat);
        copy(&term.lx, &mut bw.s_vec);
        let mut pass = BackwardPass {
            s0: problem.cost.terminal(traj.x[horizon].as_slice()),
            dv1: 0.0,
            dv2: 0.0,
        };
        for k in (0..horizon).rev() {
            if stochastic {
                // Only the stochastic merit reads them.
                copy(&bw.s_mat, &mut self.value_hessians[k]);
            }
            let q0 = bw.q_regularized(problem, traj, k, stochastic, mu) + pass.s0;
            if !bw.policy(
                &problem.bounds,
                &traj.u[k],
                &mut self.ff[k],
                &mut self.gains[k],
            ) {
                return None;
            }
            let (lqu, lquul) = bw.value_update(&self.ff[k], &self.gains[k]);
            pass.s0 = q0 + lqu + 0.5 * lquul;
            pass.dv1 += lqu;
            pass.dv2 += 0.5 * lquul;
        }
        Some(pass)
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

    /// The Q-function of knot `k` and its regularised control blocks ([`Backward::q_function`],
    /// [`Backward::regularize`]), with the knot's Jacobians read in place for the small plants
    /// ([`reads_in_place`]) and by their nonzero pattern otherwise: the same terms in the same
    /// order either way, so the same numbers.
    fn q_regularized(
        &mut self,
        problem: &Problem,
        traj: &Trajectory,
        k: usize,
        stochastic: bool,
        mu: f64,
    ) -> f64 {
        match (self.qx.len(), self.qu.len()) {
            (2, 1) => self.q_in_place::<2, 1>(problem, traj, k, stochastic, mu),
            (2, 2) => self.q_in_place::<2, 2>(problem, traj, k, stochastic, mu),
            (4, 2) => self.q_in_place::<4, 2>(problem, traj, k, stochastic, mu),
            (4, 4) => self.q_in_place::<4, 4>(problem, traj, k, stochastic, mu),
            (8, 4) => self.q_in_place::<8, 4>(problem, traj, k, stochastic, mu),
            (nx, nu) => {
                // The pattern is not built for the sizes read in place: reading it there would
                // see zero Jacobians. A size added to one list must be added to the other.
                assert!(!reads_in_place(nx, nu), "{nx}x{nu} is read in place");
                let (lin, sp) = (&traj.lin[k], &traj.sparse[k]);
                let cx = |i: usize| &sp.cx[i];
                let cu = |i: usize| &sp.cu[i];
                let q0 = self.q_function(problem, traj, k, stochastic, (&sp.a, &sp.b), (cx, cu));
                self.regularize(&sp.b, lin, mu);
                q0
            }
        }
    }

    fn q_in_place<const NX: usize, const NU: usize>(
        &mut self,
        problem: &Problem,
        traj: &Trajectory,
        k: usize,
        stochastic: bool,
        mu: f64,
    ) -> f64 {
        let lin = &traj.lin[k];
        let (a, b) = (
            SmallDense::<NX, NX>::of(&lin.a),
            SmallDense::<NX, NU>::of(&lin.b),
        );
        let cx = |i: usize| SmallDense::<NX, NX>::of(&lin.cx[i]);
        let cu = |i: usize| SmallDense::<NX, NU>::of(&lin.cu[i]);
        let q0 = self.q_function(problem, traj, k, stochastic, (a, b), (cx, cu));
        self.regularize(b, lin, mu);
        q0
    }

    /// The Q-function of knot `k` (Todorov & Li 2005) from the value `(S, s)` of knot `k + 1`, into
    /// `qx, qu, qxx, quu, qux`; returns its constant term `Δ l + ½ Σ c_iᵀ S c_i` (without `s`).
    /// The products take A, B, Cx, Cu by their nonzeros (see `sparse`): n·nnz, not n³.
    fn q_function<X: ColumnProducts, U: ColumnProducts>(
        &mut self,
        problem: &Problem,
        traj: &Trajectory,
        k: usize,
        stochastic: bool,
        (a, b): (X, U),
        (cx_of, cu_of): (impl Fn(usize) -> X, impl Fn(usize) -> U),
    ) -> f64 {
        let (lin, d) = (&traj.lin[k], &traj.derivs[k]);
        let mut q0 = problem
            .cost
            .running(k, traj.x[k].as_slice(), traj.u[k].as_slice());
        copy(&d.lx, &mut self.qx);
        a.tr_mul_vec_add(1.0, self.s_vec.as_slice(), self.qx.as_mut_slice());
        copy(&d.lu, &mut self.qu);
        b.tr_mul_vec_add(1.0, self.s_vec.as_slice(), self.qu.as_mut_slice());
        a.right_mul(&self.s_mat, &mut self.sa);
        b.right_mul(&self.s_mat, &mut self.sb);
        copy(&d.lxx, &mut self.qxx);
        transpose(&self.sa, &mut self.sat);
        a.right_mul_add(&self.sat, &mut self.qxx);
        copy(&d.luu, &mut self.quu);
        b.tr_mul_add(1.0, &self.sb, &mut self.quu);
        copy(&d.lux, &mut self.qux);
        b.tr_mul_add(1.0, &self.sa, &mut self.qux);
        if stochastic && lin.noise != NoiseKind::None {
            for i in 0..lin.c.ncols() {
                self.sc.gemv(1.0, &self.s_mat, &lin.c.column(i), 0.0);
                q0 += 0.5 * lin.c.column(i).dot(&self.sc);
                if lin.noise == NoiseKind::Dependent {
                    let (cx, cu) = (cx_of(i), cu_of(i));
                    cx.tr_mul_vec_add(1.0, self.sc.as_slice(), self.qx.as_mut_slice());
                    cu.tr_mul_vec_add(1.0, self.sc.as_slice(), self.qu.as_mut_slice());
                    cx.right_mul(&self.s_mat, &mut self.scx);
                    cu.right_mul(&self.s_mat, &mut self.scu);
                    transpose(&self.scx, &mut self.sat);
                    cx.right_mul_add(&self.sat, &mut self.qxx);
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

    /// The policy `δu = l + L δx` of the knot: the feedforward step `l` from the box QP
    /// `min ½ lᵀ Q_uu l + Q_uᵀ l` over `lower − ū ≤ l ≤ upper − ū` on the regularised `Q_uu`
    /// (projected Newton, Tassa, Mansard & Todorov 2014), warm-started at the previous `l`; the
    /// gains `L = −Q_uu⁻¹ Q_ux` on its free components, zero on the clamped ones. Without limits
    /// the QP is one Newton step and is not run. (Skipping it also whenever the Newton step
    /// happens to land inside a finite box would be the same mathematics, but the QP reaches
    /// that point along another sequence of roundings; the stochastic single joint, whose
    /// optimum is flat in the stiffness, then settles 3 % away in expected cost.) False when
    /// `Q_uu` is not positive definite.
    fn policy(
        &self,
        bounds: &Bounds,
        u: &DVector<f64>,
        l: &mut DVector<f64>,
        gain: &mut DMatrix<f64>,
    ) -> bool {
        let nu = u.len();
        let quu = &self.quu_reg;
        let h = |i: usize, j: usize| quu[(i, j)];
        let mut lower = [0.0; MAX_QP];
        let mut upper = [0.0; MAX_QP];
        for j in 0..nu {
            lower[j] = bounds.lower[j] - u[j];
            upper[j] = bounds.upper[j] - u[j];
        }
        let unbounded = (0..nu).all(|j| lower[j] == f64::NEG_INFINITY && upper[j] == f64::INFINITY);
        // Written in place, never moved (see `SmallCholesky::EMPTY`).
        let mut factor = SmallCholesky::EMPTY;
        let (x, free, factored) = if unbounded {
            let all = [0, 1, 2, 3, 4, 5, 6, 7];
            match newton_step(h, self.qu.as_slice(), &all[..nu], &mut factor) {
                None => return false,
                Some(x) => (x, [true; MAX_QP], true),
            }
        } else {
            let qp = solve_box_qp(
                h,
                self.qu.as_slice(),
                &lower[..nu],
                &upper[..nu],
                l.as_slice(),
                &mut factor,
            );
            if qp.status == QpStatus::NotPositiveDefinite {
                return false;
            }
            (qp.x, qp.free, qp.factored)
        };
        l.as_mut_slice().copy_from_slice(&x[..nu]);
        zero(gain);
        if factored {
            let mut idx = [0usize; MAX_QP];
            let mut nfree = 0;
            for j in (0..nu).filter(|&j| free[j]) {
                idx[nfree] = j;
                nfree += 1;
            }
            let idx = &idx[..nfree];
            match gain.ncols() {
                2 => self.free_gains::<2>(&factor, idx, gain),
                4 => self.free_gains::<4>(&factor, idx, gain),
                8 => self.free_gains::<8>(&factor, idx, gain),
                _ => {
                    let mut col = [0.0; MAX_QP];
                    for c in 0..gain.ncols() {
                        for (a, &j) in idx.iter().enumerate() {
                            col[a] = self.qux_reg[(j, c)];
                        }
                        factor.solve(&mut col[..nfree]);
                        for (a, &j) in idx.iter().enumerate() {
                            gain[(j, c)] = -col[a];
                        }
                    }
                }
            }
        }
        true
    }

    /// The gains `L = −Q_uu⁻¹ Q_ux` on the free controls `idx` for the paper's state sizes:
    /// all `N` columns solved at once ([`SmallCholesky::solve_many`], the same numbers as one
    /// column at a time).
    fn free_gains<const N: usize>(
        &self,
        factor: &SmallCholesky,
        idx: &[usize],
        gain: &mut DMatrix<f64>,
    ) {
        let (nu, qux) = (self.qux_reg.nrows(), self.qux_reg.as_slice());
        let mut cols = [[0.0; MAX_QP]; N];
        for (c, col) in cols.iter_mut().enumerate() {
            for (a, &j) in idx.iter().enumerate() {
                col[a] = qux[c * nu + j];
            }
        }
        factor.solve_many(&mut cols);
        let g = gain.as_mut_slice();
        for (c, col) in cols.iter().enumerate() {
            for (a, &j) in idx.iter().enumerate() {
                g[c * nu + j] = -col[a];
            }
        }
    }

    /// Value function update (Tassa 2012 form, valid with regularisation and clamping):
    /// `s = Q_x + Lᵀ Q_uu l + Lᵀ Q_u + Q_uxᵀ l`, `S = Q_xx + Lᵀ Q_uu L + Lᵀ Q_ux + Q_uxᵀ L`.
    /// Returns `(lᵀ Q_u, lᵀ Q_uu l)` for `s_0` and the expected improvement.
    fn value_update(&mut self, l: &DVector<f64>, gain: &DMatrix<f64>) -> (f64, f64) {
        let nu = l.len();
        let (lqu, lquul) = match (self.qx.len(), nu) {
            (2, 1) => self.value_terms::<2, 1>(l, gain),
            (2, 2) => self.value_terms::<2, 2>(l, gain),
            (4, 2) => self.value_terms::<4, 2>(l, gain),
            (4, 4) => self.value_terms::<4, 4>(l, gain),
            (8, 4) => self.value_terms::<8, 4>(l, gain),
            _ => self.value_terms_dynamic(l, gain),
        };
        // S = Q_xx + Lᵀ (Q_uu L + Q_ux) + Q_uxᵀ L as 2m rank-one updates, each an axpy on
        // contiguous columns of the transposed thin factors (nalgebra's transposed products
        // are plain dot loops).
        transpose(gain, &mut self.lt);
        transpose(&self.qux, &mut self.xt);
        let n = self.s_mat.nrows();
        let (gd, td) = (gain.as_slice(), self.t_mn.as_slice());
        let (ltd, xtd) = (self.lt.as_slice(), self.xt.as_slice());
        let sd = self.s_mat.as_mut_slice();
        sd.copy_from_slice(self.qxx.as_slice());
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

    /// [`Backward::value_terms_dynamic`] for the paper's plant sizes, in fixed-size loops on the
    /// column-major storage: nalgebra's dynamic calls cost more than their few products there.
    /// The same operations in the same order as nalgebra 0.35's (`gemv`: one column at a time,
    /// `y += A_{:,j} x_j`; `dot` of short dynamic vectors: `0 + Σ` from the first term on;
    /// `gemv_tr`: `y_j += dot(A_{:,j}, x)`; `gemm` below 6 rows or columns: a `gemv` per
    /// column), so the same numbers to the bit (`value_terms_match_nalgebra_bit_for_bit`).
    fn value_terms<const NX: usize, const NU: usize>(
        &mut self,
        l: &DVector<f64>,
        gain: &DMatrix<f64>,
    ) -> (f64, f64) {
        let dot = |a: &[f64], b: &[f64]| {
            let mut r = 0.0;
            for k in 0..NU {
                r += a[k] * b[k];
            }
            r
        };
        let (l, gd) = (&l.as_slice()[..NU], &gain.as_slice()[..NU * NX]);
        let quu = &self.quu.as_slice()[..NU * NU];
        let qu = &self.qu.as_slice()[..NU];
        let mut tm = [0.0; NU];
        for j in 0..NU {
            for i in 0..NU {
                let p = quu[j * NU + i] * l[j];
                tm[i] = if j == 0 { p } else { p + tm[i] };
            }
        }
        let (lqu, lquul) = (dot(l, qu), dot(l, &tm));
        for i in 0..NU {
            tm[i] += qu[i];
        }
        self.t_m.as_mut_slice().copy_from_slice(&tm);
        let qux = &self.qux.as_slice()[..NU * NX];
        let (qx, sv) = (
            &self.qx.as_slice()[..NX],
            &mut self.s_vec.as_mut_slice()[..NX],
        );
        sv.copy_from_slice(qx);
        for j in 0..NX {
            sv[j] += dot(&gd[j * NU..], &tm);
            sv[j] += dot(&qux[j * NU..], l);
        }
        let tmn = &mut self.t_mn.as_mut_slice()[..NU * NX];
        for c in 0..NX {
            let col = &mut tmn[c * NU..(c + 1) * NU];
            col.copy_from_slice(&qux[c * NU..(c + 1) * NU]);
            for j in 0..NU {
                for i in 0..NU {
                    col[i] += quu[j * NU + i] * gd[c * NU + j];
                }
            }
        }
        (lqu, lquul)
    }
}

/// The unconstrained Newton step `x = −H⁻¹ g`, with the Cholesky factor of `H` over the indices
/// `idx` (all of them) written into `factor`; `None` when `H` is not positive definite.
fn newton_step(
    h: impl Fn(usize, usize) -> f64 + Copy,
    g: &[f64],
    idx: &[usize],
    factor: &mut SmallCholesky,
) -> Option<[f64; MAX_QP]> {
    if !factor.factorize(h, idx) {
        return None;
    }
    let mut x = [0.0; MAX_QP];
    for (a, &i) in idx.iter().enumerate() {
        x[a] = -g[i];
    }
    factor.solve(&mut x[..idx.len()]);
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Entries of every kind the products meet: ordinary values, exact zeros of both signs
    /// (whose sums depend on the order and the starting zero) and values far apart in scale.
    fn entries(seed: &mut u64, n: usize) -> Vec<f64> {
        (0..n)
            .map(|_| {
                *seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let u = (*seed >> 11) as f64 / (1u64 << 53) as f64;
                match *seed >> 60 {
                    0 => 0.0,
                    1 => -0.0,
                    2 => (u - 0.5) * 1e12,
                    3 => (u - 0.5) * 1e-9,
                    _ => u - 0.5,
                }
            })
            .collect()
    }

    fn filled(nx: usize, nu: usize, seed: &mut u64) -> Backward {
        let mut b = Backward::new(nx, nu);
        b.quu = DMatrix::from_vec(nu, nu, entries(seed, nu * nu));
        b.qu = DVector::from_vec(entries(seed, nu));
        b.qx = DVector::from_vec(entries(seed, nx));
        b.qux = DMatrix::from_vec(nu, nx, entries(seed, nu * nx));
        // Stale contents that both versions must overwrite.
        b.t_m = DVector::from_vec(entries(seed, nu));
        b.s_vec = DVector::from_vec(entries(seed, nx));
        b.t_mn = DMatrix::from_vec(nu, nx, entries(seed, nu * nx));
        b
    }

    #[test]
    fn value_terms_match_nalgebra_bit_for_bit() {
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let mut seed = 7;
        for (nx, nu) in [(2, 1), (2, 2), (4, 2), (4, 4), (8, 4)] {
            for _ in 0..200 {
                let start = seed;
                let mut fixed = filled(nx, nu, &mut seed);
                let mut dynamic = filled(nx, nu, &mut { start });
                let l = DVector::from_vec(entries(&mut seed, nu));
                let gain = DMatrix::from_vec(nu, nx, entries(&mut seed, nu * nx));
                let a = match (nx, nu) {
                    (2, 1) => fixed.value_terms::<2, 1>(&l, &gain),
                    (2, 2) => fixed.value_terms::<2, 2>(&l, &gain),
                    (4, 2) => fixed.value_terms::<4, 2>(&l, &gain),
                    (4, 4) => fixed.value_terms::<4, 4>(&l, &gain),
                    _ => fixed.value_terms::<8, 4>(&l, &gain),
                };
                let b = dynamic.value_terms_dynamic(&l, &gain);
                assert_eq!(bits(&[a.0, a.1]), bits(&[b.0, b.1]), "{nx}x{nu}");
                assert_eq!(bits(fixed.t_m.as_slice()), bits(dynamic.t_m.as_slice()));
                assert_eq!(bits(fixed.s_vec.as_slice()), bits(dynamic.s_vec.as_slice()));
                assert_eq!(bits(fixed.t_mn.as_slice()), bits(dynamic.t_mn.as_slice()));
            }
        }
    }
}
