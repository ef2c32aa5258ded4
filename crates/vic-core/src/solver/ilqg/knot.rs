//! One knot of the backward pass on the stack, for the paper's plant sizes (the single joint with
//! torque or torque and stiffness, the two-link arm with either, the VSA arm): the Q-function, its
//! regularisation and the value update of [`super::backward`] with every size a constant, so that
//! the compiler unrolls the products and keeps the blocks in registers instead of walking
//! `DMatrix` storage through run-time sizes and bounds checks (the backward pass is most of a
//! solve of the two-link reach that way).
//!
//! The operations are the dynamic path's, in its order: the products by the Jacobians' nonzeros
//! in ascending row order (`sparse::nonzero_dot`), nalgebra 0.35's `gemv` and `dot` for the
//! noise columns, the value update's loops. So the numbers are the same to the bit
//! (`the_fixed_knot_matches_the_dynamic_one_bit_for_bit`), and the choice of path is invisible in
//! a plan.

use super::policy::policy;
use super::{Bounds, CostDerivatives, Linearization, NoiseKind};
use crate::solver::sparse::nonzero_dot;

/// A matrix with `R` rows and `C` columns, column-major like nalgebra: `m[j][i]` is entry (i, j).
pub(super) type Mat<const R: usize, const C: usize> = [[f64; R]; C];

/// The `R × C` view of a matrix's column-major storage.
pub(super) fn view<const R: usize, const C: usize>(m: &nalgebra::DMatrix<f64>) -> &Mat<R, C> {
    debug_assert_eq!((m.nrows(), m.ncols()), (R, C));
    let (columns, rest) = m.as_slice().as_chunks::<R>();
    debug_assert!(rest.is_empty());
    columns.try_into().expect("an R × C matrix")
}

fn vector<const N: usize>(v: &nalgebra::DVector<f64>) -> &[f64; N] {
    v.as_slice().try_into().expect("an N-vector")
}

/// `out = S M` by the nonzeros of `M` (`ColumnProducts::right_mul`): each column of `out` starts
/// at +0 and adds `m_ij S_{:,i}` for the nonzero `m_ij` in ascending `i`.
#[inline(always)]
fn right_mul<const R: usize, const C: usize>(s: &Mat<R, R>, m: &Mat<R, C>) -> Mat<R, C> {
    let mut out = [[0.0; R]; C];
    right_mul_add(s, m, &mut out);
    out
}

/// `out += S M` by the nonzeros of `M` (`ColumnProducts::right_mul_add`).
#[inline(always)]
fn right_mul_add<const R: usize, const C: usize>(
    s: &Mat<R, R>,
    m: &Mat<R, C>,
    out: &mut Mat<R, C>,
) {
    for (col, mj) in out.iter_mut().zip(m) {
        for (&a, si) in mj.iter().zip(s) {
            if a != 0.0 {
                for (o, s) in col.iter_mut().zip(si) {
                    *o += a * s;
                }
            }
        }
    }
}

/// `out += α Mᵀ X` by the nonzeros of `M` (`ColumnProducts::tr_mul_add`).
#[inline(always)]
fn tr_mul_add<const R: usize, const C: usize, const Q: usize>(
    alpha: f64,
    m: &Mat<R, C>,
    x: &Mat<R, Q>,
    out: &mut Mat<C, Q>,
) {
    for (oc, xc) in out.iter_mut().zip(x) {
        for (o, mj) in oc.iter_mut().zip(m) {
            *o += alpha * nonzero_dot(mj, xc);
        }
    }
}

/// `y += Mᵀ v` by the nonzeros of `M` (`ColumnProducts::tr_mul_vec_add` with α = 1).
#[inline(always)]
fn tr_mul_vec_add<const R: usize, const C: usize>(m: &Mat<R, C>, v: &[f64; R], y: &mut [f64; C]) {
    for (yj, mj) in y.iter_mut().zip(m) {
        *yj += 1.0 * nonzero_dot(mj, v);
    }
}

#[inline(always)]
fn transpose<const R: usize, const C: usize>(m: &Mat<R, C>) -> Mat<C, R> {
    let mut t = [[0.0; C]; R];
    for (j, mj) in m.iter().enumerate() {
        for (i, &v) in mj.iter().enumerate() {
            t[i][j] = v;
        }
    }
    t
}

/// nalgebra 0.35's `dot` of two dynamic vectors: eight partial sums over whole blocks of eight,
/// folded pairwise into a sum from +0, then the remaining terms one by one.
#[inline(always)]
fn nalgebra_dot<const N: usize>(a: &[f64; N], b: &[f64; N]) -> f64 {
    let (mut res, mut i) = (0.0, 0);
    let mut acc = [0.0; 8];
    while N - i >= 8 {
        for (k, acc) in acc.iter_mut().enumerate() {
            *acc += a[i + k] * b[i + k];
        }
        i += 8;
    }
    res += acc[0] + acc[4];
    res += acc[1] + acc[5];
    res += acc[2] + acc[6];
    res += acc[3] + acc[7];
    for k in i..N {
        res += a[k] * b[k];
    }
    res
}

/// nalgebra 0.35's `y.gemv(1, S, c, 0)`: `y = S_{:,0} c_0`, then `y = S_{:,j} c_j + y`.
#[inline(always)]
fn nalgebra_gemv<const N: usize>(s: &Mat<N, N>, c: &[f64; N]) -> [f64; N] {
    let mut y = [0.0; N];
    for (j, (sj, &cj)) in s.iter().zip(c).enumerate() {
        for (y, &v) in y.iter_mut().zip(sj) {
            *y = if j == 0 { v * cj } else { v * cj + *y };
        }
    }
    y
}

/// The value function of a knot, `s₀ + sᵀ δx + ½ δxᵀ S δx`, without its constant.
#[derive(Debug, Clone, Copy)]
pub(super) struct Value<const NX: usize> {
    pub s_mat: Mat<NX, NX>,
    pub s_vec: [f64; NX],
}

impl<const NX: usize> Value<NX> {
    /// The final cost's expansion, the value of the last knot.
    pub(super) fn terminal(d: &CostDerivatives) -> Self {
        Value {
            s_mat: *view(&d.lxx),
            s_vec: *vector(&d.lx),
        }
    }
}

/// The Q-function of one knot (Todorov & Li 2005) and its regularised control blocks.
#[derive(Debug, Clone, Copy)]
pub(super) struct Knot<const NX: usize, const NU: usize> {
    qx: [f64; NX],
    qu: [f64; NU],
    qxx: Mat<NX, NX>,
    quu: Mat<NU, NU>,
    /// `Q_ux` (NU × NX).
    qux: Mat<NU, NX>,
    quu_reg: Mat<NU, NU>,
    qux_reg: Mat<NU, NX>,
}

impl<const NX: usize, const NU: usize> Knot<NX, NU> {
    pub(super) const EMPTY: Self = Knot {
        qx: [0.0; NX],
        qu: [0.0; NU],
        qxx: [[0.0; NX]; NX],
        quu: [[0.0; NU]; NU],
        qux: [[0.0; NU]; NX],
        quu_reg: [[0.0; NU]; NU],
        qux_reg: [[0.0; NU]; NX],
    };

    /// The Q-function from the value `v` of the next knot (`Backward::q_function`), and its
    /// regularisation by μ (`Backward::regularize`); returns the constant term `running + ½ Σ
    /// c_iᵀ S c_i` (without `s₀`).
    #[inline(always)]
    pub(super) fn expand(
        &mut self,
        v: &Value<NX>,
        (lin, d): (&Linearization, &CostDerivatives),
        running: f64,
        stochastic: bool,
        mu: f64,
    ) -> f64 {
        let (a, b) = (view::<NX, NX>(&lin.a), view::<NX, NU>(&lin.b));
        let (s, sv) = (&v.s_mat, &v.s_vec);
        let mut q0 = running;
        self.qx = *vector(&d.lx);
        tr_mul_vec_add(a, sv, &mut self.qx);
        self.qu = *vector(&d.lu);
        tr_mul_vec_add(b, sv, &mut self.qu);
        let sa = right_mul(s, a);
        let sb = right_mul(s, b);
        self.qxx = *view(&d.lxx);
        right_mul_add(&transpose(&sa), a, &mut self.qxx);
        self.quu = *view(&d.luu);
        tr_mul_add(1.0, b, &sb, &mut self.quu);
        self.qux = *view(&d.lux);
        tr_mul_add(1.0, b, &sa, &mut self.qux);
        if stochastic && lin.noise != NoiseKind::None {
            let (columns, _) = lin.c.as_slice().as_chunks::<NX>();
            for (i, c) in columns.iter().enumerate() {
                let sc = nalgebra_gemv(s, c);
                q0 += 0.5 * nalgebra_dot(c, &sc);
                if lin.noise == NoiseKind::Dependent {
                    let (cx, cu) = (view::<NX, NX>(&lin.cx[i]), view::<NX, NU>(&lin.cu[i]));
                    tr_mul_vec_add(cx, &sc, &mut self.qx);
                    tr_mul_vec_add(cu, &sc, &mut self.qu);
                    let scx = right_mul(s, cx);
                    let scu = right_mul(s, cu);
                    right_mul_add(&transpose(&scx), cx, &mut self.qxx);
                    tr_mul_add(1.0, cu, &scu, &mut self.quu);
                    tr_mul_add(1.0, cu, &scx, &mut self.qux);
                }
            }
        }
        self.quu_reg = self.quu;
        self.qux_reg = self.qux;
        if mu > 0.0 {
            tr_mul_add(mu, b, b, &mut self.quu_reg);
            tr_mul_add(mu, b, a, &mut self.qux_reg);
            for (j, col) in self.quu_reg.iter_mut().enumerate() {
                col[j] += mu * 1e-6;
            }
        }
        q0
    }

    /// The knot's policy from the box QP ([`policy`]) into `l` and `gain` (NU × NX); false when
    /// `Q_uu` is not positive definite.
    #[inline(always)]
    pub(super) fn policy(
        &self,
        bounds: &Bounds,
        u: &[f64],
        l: &mut [f64],
        gain: &mut [f64],
    ) -> bool {
        policy::<NU>(
            self.quu_reg.as_flattened(),
            &self.qu,
            self.qux_reg.as_flattened(),
            bounds,
            u,
            l,
            gain,
        )
    }

    /// The value of this knot under the policy `(l, L)` (`Backward::value_update`, Tassa 2012):
    /// `s = Q_x + Lᵀ (Q_uu l + Q_u) + Q_uxᵀ l`, `S = Q_xx + Lᵀ (Q_uu L + Q_ux) + Q_uxᵀ L`,
    /// symmetrised. Returns `(lᵀ Q_u, lᵀ Q_uu l)`.
    #[inline(always)]
    pub(super) fn value_update(&self, l: &[f64], gain: &[f64], v: &mut Value<NX>) -> (f64, f64) {
        let dot = |a: &[f64], b: &[f64]| {
            let mut r = 0.0;
            for k in 0..NU {
                r += a[k] * b[k];
            }
            r
        };
        let l: &[f64; NU] = l.try_into().expect("NU controls");
        let gain: &Mat<NU, NX> = gain
            .as_chunks::<NU>()
            .0
            .try_into()
            .expect("an NU × NX gain");
        let (quu, qu, qux) = (&self.quu, &self.qu, &self.qux);
        // t = Q_uu l by columns (nalgebra's gemv with β = 0), then + Q_u.
        let mut tm = [0.0; NU];
        for (j, qj) in quu.iter().enumerate() {
            for (t, &q) in tm.iter_mut().zip(qj) {
                let p = q * l[j];
                *t = if j == 0 { p } else { p + *t };
            }
        }
        let (lqu, lquul) = (dot(l, qu), dot(l, &tm));
        for (t, q) in tm.iter_mut().zip(qu) {
            *t += q;
        }
        let sv = &mut v.s_vec;
        *sv = self.qx;
        for j in 0..NX {
            sv[j] += dot(&gain[j], &tm);
            sv[j] += dot(&qux[j], l);
        }
        // T = Q_uu L + Q_ux.
        let mut tmn = *qux;
        for (col, gc) in tmn.iter_mut().zip(gain) {
            for (qj, &g) in quu.iter().zip(gc) {
                for (c, &q) in col.iter_mut().zip(qj) {
                    *c += q * g;
                }
            }
        }
        // S = Q_xx + Lᵀ T + Q_uxᵀ L as 2·NU rank-one updates.
        let (lt, xt) = (transpose(gain), transpose(qux));
        let sd = &mut v.s_mat;
        *sd = self.qxx;
        for (j, col) in sd.iter_mut().enumerate() {
            for r in 0..NU {
                let (t, g) = (tmn[j][r], gain[j][r]);
                for ((s, l), x) in col.iter_mut().zip(&lt[r]).zip(&xt[r]) {
                    *s += l * t + x * g;
                }
            }
        }
        // Symmetric against round-off: the average of the two triangles.
        for j in 0..NX {
            for i in j + 1..NX {
                let m = 0.5 * (sd[j][i] + sd[i][j]);
                sd[i][j] = m;
                sd[j][i] = m;
            }
        }
        (lqu, lquul)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solver::sparse::tests::pattern;
    use crate::solver::sparse::{ColumnProducts, SparseColumns};

    /// The stack products give the pattern's products bit for bit (the backward pass's numbers
    /// must not depend on which of the two reads a knot), with negative zeros, NaN and infinite
    /// entries in the Jacobian, and infinite entries in the other factor (a zero of the
    /// Jacobian must skip them, not make a NaN).
    #[test]
    fn stack_products_match_the_pattern_bit_for_bit() {
        fn check<const R: usize, const C: usize>(seed: u64) {
            let mut m = pattern(R, C, seed);
            // Negative zeros (skipped by both), and a NaN and an infinity (kept by both).
            for (i, v) in m.iter_mut().enumerate() {
                if *v == 0.0 && i % 3 == 0 {
                    *v = -0.0;
                }
            }
            if seed % 5 == 1 {
                m[(R - 1, 0)] = f64::NAN;
                m[(0, C - 1)] = f64::INFINITY;
            }
            let mut sp = SparseColumns::new(R, C);
            sp.assign(&m);
            let small = view::<R, C>(&m);
            // A NaN is compared as a NaN: IEEE 754 leaves its sign and payload open, and the
            // compiler may commute an addition, which decides whose NaN propagates.
            let bit = |v: &f64| if v.is_nan() { u64::MAX } else { v.to_bits() };
            let bits = |a: &[f64]| a.iter().map(bit).collect::<Vec<_>>();
            // An infinite entry of S, X or v against a zero of M: skipped, the term is no NaN.
            let infinite = seed % 5 == 2;
            let mut s = pattern(R, R, seed + 1);
            if infinite {
                s[(0, 0)] = f64::INFINITY;
            }
            let mut a = pattern(R, C, seed + 2);
            let mut b = *view::<R, C>(&a);
            sp.right_mul_add(&s, &mut a);
            right_mul_add(view(&s), small, &mut b);
            assert_eq!(bits(a.as_slice()), bits(b.as_flattened()), "S M, {R}x{C}");
            sp.right_mul(&s, &mut a);
            let b = right_mul(view(&s), small);
            assert_eq!(bits(a.as_slice()), bits(b.as_flattened()), "S M, {R}x{C}");
            let mut x = pattern(R, 3, seed + 3);
            if infinite {
                x[(0, 0)] = f64::INFINITY;
            }
            let mut a = pattern(C, 3, seed + 4);
            let mut b = *view::<C, 3>(&a);
            sp.tr_mul_add(0.7, &x, &mut a);
            tr_mul_add(0.7, small, view(&x), &mut b);
            assert_eq!(bits(a.as_slice()), bits(b.as_flattened()), "Mᵀ X, {R}x{C}");
            let mut v = pattern(R, 1, seed + 5);
            if infinite {
                v[(0, 0)] = f64::INFINITY;
            }
            let (mut y, mut z) = (vec![0.25; C], [0.25; C]);
            sp.tr_mul_vec_add(1.0, v.as_slice(), &mut y);
            tr_mul_vec_add(small, v.as_slice().try_into().unwrap(), &mut z);
            assert_eq!(bits(&y), bits(&z), "Mᵀ v, {R}x{C}");
        }
        for seed in 0..20 {
            check::<2, 1>(seed * 7);
            check::<2, 2>(seed * 7);
            check::<4, 2>(seed * 7);
            check::<4, 4>(seed * 7);
            check::<8, 4>(seed * 7);
        }
    }
}
