//! The nonzeros of a linearisation, column by column, for the backward pass.
//!
//! The Jacobians the solvers see are often mostly zeros: the delay-augmented plant (`Delayed`) has
//! a shift matrix plus the plant block (46 nonzeros of 42² for the single joint with a 200 ms
//! delay), its `B` is a single identity block, the noise Jacobians live in the plant block, and the
//! explicit-Euler `A = I + Δ f_x` has exact zeros and ones. The backward pass's products
//! `Aᵀ S A`, `Bᵀ S A`, … cost `n · nnz` instead of `n³` when one factor is taken by its nonzeros.
//! The pattern is read off the dense matrix at every knot (exact zeros only), so any model benefits
//! without declaring its structure, and a product skips only terms that are exactly zero. A model
//! that declares where its Jacobians can be nonzero ([`StateSupport`]: the delayed plant) has them
//! read there only, which is the same pattern at a fraction of the reads.

use crate::core::dense::zero;
use crate::core::dynamics::{Column, Linearization, NoiseKind, StateSupport};
use nalgebra::DMatrix;
use std::ops::Range;

/// A matrix stored by its nonzeros, column by column (compressed sparse column).
#[derive(Debug, Clone)]
pub struct SparseColumns {
    nrows: usize,
    /// Entries of column `j` are `start[j]..start[j + 1]`.
    start: Vec<usize>,
    /// The nonzeros' rows and values, column after column. Room for every entry is reserved but
    /// only the nonzeros are ever written: the 42-state delayed plant stores 46 of 1764 entries of
    /// `A` per knot, and a workspace that touched all of them spent a fifth of a stochastic plan
    /// faulting in and clearing memory it never read.
    row: Vec<usize>,
    val: Vec<f64>,
    /// The columns from the first to the last that holds a nonzero (empty when none does). The
    /// products `Mᵀ v` skip the empty columns outside: a skipped column would add `α · (−0)`
    /// (an empty sum is `−0`), which changes nothing for a positive or `+0` factor. The delayed
    /// plant's noise Jacobians `Cx_i` hold nonzeros in 4 of 42 columns, its `Cu_i` in none.
    occupied: Range<usize>,
}

impl SparseColumns {
    /// Room for an `nrows × ncols` matrix (no allocation when refilled at this size).
    pub fn new(nrows: usize, ncols: usize) -> Self {
        SparseColumns {
            nrows,
            start: vec![0; ncols + 1],
            row: Vec::with_capacity(nrows * ncols),
            val: Vec::with_capacity(nrows * ncols),
            occupied: 0..0,
        }
    }

    /// Number of columns.
    pub fn ncols(&self) -> usize {
        self.start.len() - 1
    }

    /// Number of stored (nonzero) entries.
    pub fn nnz(&self) -> usize {
        self.start[self.ncols()]
    }

    /// Refills from the nonzeros of `m` (same size as at construction, so the appends stay
    /// within the reserved room). Each column is read in blocks of 8 rows, and a block is
    /// visited entry by entry only if it holds a nonzero: the test ORs the entries' bits without
    /// the sign (zero exactly for `±0`; a NaN counts as nonzero, as `v != 0.0` says), which
    /// vectorises on plain integer registers. The delayed plant's columns hold 1–3 nonzeros of
    /// 42 and its noise Jacobians none outside the plant block, so most blocks are skipped
    /// whole (a mask of each block's nonzeros, built entry by entry, cost a sixth of a
    /// stochastic solve of the delayed single joint).
    pub fn assign(&mut self, m: &DMatrix<f64>) {
        self.assign_within(m, None);
    }

    /// [`SparseColumns::assign`] reading column `j` in rows `rows[j]` only, when given: the
    /// caller knows the entries outside are zero ([`StateSupport`]), and the result is the same.
    pub fn assign_within(&mut self, m: &DMatrix<f64>, rows: Option<&[Range<usize>]>) {
        debug_assert!(rows.is_none_or(|r| r.len() == m.ncols()));
        self.assign_columns(m, |j| match rows {
            Some(r) => Column::Rows(r[j].clone()),
            None => Column::Rows(0..m.nrows()),
        });
    }

    /// [`SparseColumns::assign`] reading column `j` where `columns[j]` says it can be nonzero,
    /// and a unit column's one without reading it: the caller knows the entries outside are
    /// zero and the unit entries one ([`StateSupport`]), and the result is the same.
    pub fn assign_support(&mut self, m: &DMatrix<f64>, columns: &[Column]) {
        debug_assert_eq!(columns.len(), m.ncols());
        self.assign_columns(m, |j| columns[j].clone());
    }

    fn assign_columns(&mut self, m: &DMatrix<f64>, column: impl Fn(usize) -> Column) {
        debug_assert_eq!((m.nrows(), m.ncols()), (self.nrows, self.ncols()));
        let data = m.as_slice();
        let n = self.nrows;
        self.row.clear();
        self.val.clear();
        for j in 0..m.ncols() {
            self.start[j] = self.row.len();
            let within = match column(j) {
                Column::Rows(r) => r,
                Column::Unit(i) => {
                    debug_assert_eq!(data[j * n + i], 1.0, "unit column {j}");
                    self.row.push(i);
                    self.val.push(1.0);
                    continue;
                }
            };
            let first = within.start;
            let column = &data[j * n..(j + 1) * n][within];
            for (b, block) in column.chunks(8).enumerate() {
                if block.iter().fold(0u64, |any, v| any | (v.to_bits() << 1)) == 0 {
                    continue;
                }
                for (i, &v) in block.iter().enumerate() {
                    if v != 0.0 {
                        self.row.push(first + b * 8 + i);
                        self.val.push(v);
                    }
                }
            }
        }
        let ncols = self.ncols();
        self.start[ncols] = self.row.len();
        let held = |j: &usize| self.start[j + 1] > self.start[*j];
        self.occupied = match (0..ncols).find(held) {
            Some(first) => first..(first..ncols).rfind(held).map_or(first, |j| j + 1),
            None => 0..0,
        };
    }

    /// The columns `Mᵀ v` must visit for a factor `α`: the occupied ones when `α` is `+0` or
    /// positive and finite (`α · (−0) = −0` then), else all (see `occupied`).
    fn visited(&self, alpha: f64) -> Range<usize> {
        if alpha.is_sign_positive() && alpha.is_finite() {
            self.occupied.clone()
        } else {
            0..self.ncols()
        }
    }

    /// The rows and values of column `j`'s nonzeros, in ascending row order.
    pub fn column(&self, j: usize) -> (&[usize], &[f64]) {
        let r = self.start[j]..self.start[j + 1];
        (&self.row[r.clone()], &self.val[r])
    }

    /// Row `i` of `S M` for a symmetric `S` given by `s_rows`, whose column `i` is row `i` of
    /// `S` (`S` itself when it is symmetric to the bit), into `out` (`M`'s columns long): each
    /// entry is [`ColumnProducts::right_mul`]'s (`0 + m_k s_ik`, then `+ m_k s_ik` in ascending
    /// `k`; `+0` for an empty column), to the bit. Reading a row of `S` from a column is what
    /// lets the backward pass take one row of a product where it needs it instead of forming
    /// the whole `n × n` product (see `ilqg::backward`).
    pub fn product_row(&self, s_rows: &DMatrix<f64>, i: usize, out: &mut [f64]) {
        let n = s_rows.nrows();
        debug_assert_eq!(n, self.nrows);
        let s = &s_rows.as_slice()[i * n..(i + 1) * n];
        for (c, o) in out.iter_mut().enumerate().take(self.ncols()) {
            let (rows, vals) = self.column(c);
            let mut terms = rows.iter().zip(vals);
            *o = match terms.next() {
                None => 0.0,
                Some((&k, &a)) => terms.fold(0.0 + a * s[k], |v, (&k, &a)| v + a * s[k]),
            };
        }
    }

    /// `out += α Mᵀ (S N)` for a symmetric `S` (`s_rows` as in [`SparseColumns::product_row`]),
    /// `M` this matrix and `N` sparse: [`ColumnProducts::tr_mul_add`] of `M` with `X = S N`, to
    /// the bit, from the rows of `S N` that `M` reads (`rows` is scratch, within the `n × n`
    /// it is given room for). For the delayed plant's noise term `Cuᵀ (S Cx)` those are the
    /// plant's rows, where `S Cx` itself is `n × n`.
    pub fn tr_mul_product_add(
        &self,
        alpha: f64,
        s_rows: &DMatrix<f64>,
        other: &SparseColumns,
        rows: &mut Vec<f64>,
        out: &mut DMatrix<f64>,
    ) {
        let q = other.ncols();
        debug_assert_eq!((out.nrows(), out.ncols()), (self.ncols(), q));
        for j in self.visited(alpha) {
            let (idx, vals) = self.column(j);
            rows.clear();
            rows.resize(idx.len() * q, 0.0);
            for (t, &i) in idx.iter().enumerate() {
                other.product_row(s_rows, i, &mut rows[t * q..(t + 1) * q]);
            }
            for c in 0..q {
                let dot: f64 = vals
                    .iter()
                    .enumerate()
                    .map(|(t, &a)| a * rows[t * q + c])
                    .sum();
                out[(j, c)] += alpha * dot;
            }
        }
    }

    /// `out = S M` or `out += S M` column by column, as `axpy`s on contiguous columns of `S`,
    /// which vectorise. From zero, each column's first term is written as `0 + a s` (what a
    /// cleared column plus every term gives, to the bit), so [`ColumnProducts::right_mul`]
    /// saves the clearing pass.
    fn mul_columns(&self, s: &DMatrix<f64>, out: &mut DMatrix<f64>, first: First) {
        let p = s.nrows();
        debug_assert_eq!(s.ncols(), self.nrows);
        debug_assert_eq!((out.nrows(), out.ncols()), (p, self.ncols()));
        let sd = s.as_slice();
        let od = out.as_mut_slice();
        for j in 0..self.ncols() {
            let col = &mut od[j * p..(j + 1) * p];
            let (rows, vals) = self.column(j);
            let mut terms = rows.iter().zip(vals);
            match first {
                First::Out => {}
                First::Zero => {
                    let Some((&i, &a)) = terms.next() else {
                        col.fill(0.0);
                        continue;
                    };
                    for (o, s) in col.iter_mut().zip(&sd[i * p..(i + 1) * p]) {
                        *o = 0.0 + a * s;
                    }
                }
            }
            for (&i, &a) in terms {
                for (o, s) in col.iter_mut().zip(&sd[i * p..(i + 1) * p]) {
                    *o += a * s;
                }
            }
        }
    }
}

/// What a column of [`SparseColumns::mul_columns`] starts from.
#[derive(Clone, Copy)]
enum First {
    /// The output as it is (`out += S M`).
    Out,
    /// Zero (`out = S M`).
    Zero,
}

/// The products of the backward pass with a Jacobian `M` (A, B or a noise Jacobian) taken by its
/// nonzeros: every term `m_ij · x` with `m_ij = 0` is skipped and the others are added in
/// ascending row order, so that [`SparseColumns`] and the backward pass on the stack (the
/// `ilqg::knot` module, for the small plants) compute the same numbers bit for bit.
pub trait ColumnProducts {
    /// `y += α Mᵀ v`.
    fn tr_mul_vec_add(&self, alpha: f64, v: &[f64], y: &mut [f64]);

    /// `out = S M` for a dense `S` (p × nrows); `out` is p × ncols.
    fn right_mul(&self, s: &DMatrix<f64>, out: &mut DMatrix<f64>) {
        zero(out);
        self.right_mul_add(s, out);
    }

    /// `out += S M` for a dense `S` (p × nrows); `out` is p × ncols.
    fn right_mul_add(&self, s: &DMatrix<f64>, out: &mut DMatrix<f64>);

    /// `out += α Mᵀ X` for a dense `X` (nrows × q); `out` is ncols × q.
    fn tr_mul_add(&self, alpha: f64, x: &DMatrix<f64>, out: &mut DMatrix<f64>);
}

impl<T: ColumnProducts> ColumnProducts for &T {
    fn tr_mul_vec_add(&self, alpha: f64, v: &[f64], y: &mut [f64]) {
        (**self).tr_mul_vec_add(alpha, v, y)
    }
    fn right_mul(&self, s: &DMatrix<f64>, out: &mut DMatrix<f64>) {
        (**self).right_mul(s, out)
    }
    fn right_mul_add(&self, s: &DMatrix<f64>, out: &mut DMatrix<f64>) {
        (**self).right_mul_add(s, out)
    }
    fn tr_mul_add(&self, alpha: f64, x: &DMatrix<f64>, out: &mut DMatrix<f64>) {
        (**self).tr_mul_add(alpha, x, out)
    }
}

impl ColumnProducts for SparseColumns {
    /// `out = S M` without clearing `out` first: a column's first nonzero writes `0 + a s`,
    /// what the cleared column plus [`ColumnProducts::right_mul_add`] gives (to the sign of a
    /// zero), and an empty column is cleared. On the 42-state delayed plant every column of `A`
    /// has a nonzero, so the pass that cleared the whole product is saved.
    fn right_mul(&self, s: &DMatrix<f64>, out: &mut DMatrix<f64>) {
        self.mul_columns(s, out, First::Zero);
    }

    fn tr_mul_vec_add(&self, alpha: f64, v: &[f64], y: &mut [f64]) {
        let cols = self.visited(alpha);
        for (j, yj) in y.iter_mut().enumerate().take(cols.end).skip(cols.start) {
            let (rows, vals) = self.column(j);
            let dot: f64 = rows.iter().zip(vals).map(|(&i, &a)| a * v[i]).sum();
            *yj += alpha * dot;
        }
    }

    fn right_mul_add(&self, s: &DMatrix<f64>, out: &mut DMatrix<f64>) {
        self.mul_columns(s, out, First::Out);
    }

    fn tr_mul_add(&self, alpha: f64, x: &DMatrix<f64>, out: &mut DMatrix<f64>) {
        let n = self.nrows;
        debug_assert_eq!(x.nrows(), n);
        debug_assert_eq!((out.nrows(), out.ncols()), (self.ncols(), x.ncols()));
        let xd = x.as_slice();
        let rows_out = out.nrows();
        let od = out.as_mut_slice();
        let cols = self.visited(alpha);
        for c in 0..x.ncols() {
            let xc = &xd[c * n..(c + 1) * n];
            let oc = &mut od[c * rows_out..(c + 1) * rows_out];
            for (j, o) in oc.iter_mut().enumerate().take(cols.end).skip(cols.start) {
                let (rows, vals) = self.column(j);
                let dot: f64 = rows.iter().zip(vals).map(|(&i, &a)| a * xc[i]).sum();
                *o += alpha * dot;
            }
        }
    }
}

/// `Σ_i m_i x_i` over the nonzero `m_i`, in order (the sum [`SparseColumns`] forms). A zero
/// `m_i` adds −0 instead of being filtered out: `s + (−0) = s` exactly for every `s` (±0, ±∞
/// and NaN included), so the sum is the filtered one to the bit, without a branch per entry
/// (the filter cost the two-link reach 15 % of a solve).
#[inline(always)]
pub(crate) fn nonzero_dot<const R: usize>(m: &[f64; R], x: &[f64]) -> f64 {
    m.iter()
        .zip(&x[..R])
        .map(|(&a, &x)| if a != 0.0 { a * x } else { -0.0 })
        .sum()
}

/// The nonzeros of one knot's `A`, `B` and noise Jacobians `Cx_i`, `Cu_i`.
#[derive(Debug, Clone)]
pub struct SparseLinearization {
    pub a: SparseColumns,
    pub b: SparseColumns,
    pub cx: Vec<SparseColumns>,
    pub cu: Vec<SparseColumns>,
}

impl SparseLinearization {
    pub fn new(nx: usize, nu: usize, nw: usize) -> Self {
        SparseLinearization {
            a: SparseColumns::new(nx, nx),
            b: SparseColumns::new(nx, nu),
            cx: (0..nw).map(|_| SparseColumns::new(nx, nx)).collect(),
            cu: (0..nw).map(|_| SparseColumns::new(nx, nu)).collect(),
        }
    }

    /// Refills from a dense linearisation (the noise Jacobians only when state-dependent),
    /// reading the Jacobians only within the model's `support` when it has one.
    pub fn assign(&mut self, lin: &Linearization, support: Option<&StateSupport>) {
        match support {
            Some(s) => {
                self.a.assign_support(&lin.a, &s.a);
                self.b.assign_support(&lin.b, &s.b);
            }
            None => {
                self.a.assign(&lin.a);
                self.b.assign(&lin.b);
            }
        }
        if lin.noise == NoiseKind::Dependent {
            for (s, d) in self.cx.iter_mut().zip(&lin.cx) {
                s.assign_within(d, support.map(|s| &s.cx[..]));
            }
            for (s, d) in self.cu.iter_mut().zip(&lin.cu) {
                s.assign_within(d, support.map(|s| &s.cu[..]));
            }
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A random `r × c` matrix with about half its entries exactly zero.
    pub(crate) fn pattern(r: usize, c: usize, seed: u64) -> DMatrix<f64> {
        let mut s = seed;
        DMatrix::from_fn(r, c, |_, _| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let v = ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0;
            if v.abs() < 0.5 { 0.0 } else { v }
        })
    }

    /// A row of `S M` read from the columns of `S` (or of `Sᵀ` for an `S` that is not
    /// symmetric) is that row of `right_mul`'s product, and `Mᵀ (S N)` from those rows is
    /// `tr_mul_add` on the whole product, bit for bit: with zeros of both signs in `S`, empty
    /// and dense columns in `M` and `N`, and a dirty output.
    #[test]
    fn products_from_rows_are_the_whole_products_to_the_bit() {
        for seed in 0..60 {
            let (n, q) = (9, [9, 4, 1][seed as usize % 3]);
            let signed = |v: f64| if v == 0.0 && seed % 2 == 0 { -0.0 } else { v };
            let raw = pattern(n, n, seed + 300).map(signed);
            let symmetric = seed % 4 != 3;
            let s = if symmetric {
                &raw + raw.transpose()
            } else {
                raw.clone()
            };
            let s_rows = if symmetric { s.clone() } else { s.transpose() };
            let mut nm = pattern(n, q, seed + 400);
            nm.column_mut(seed as usize % q).fill(0.0);
            let mut m = pattern(n, 3, seed + 500);
            m.column_mut(seed as usize % 3).fill(0.0);
            let (mut sp_n, mut sp_m) = (SparseColumns::new(n, q), SparseColumns::new(n, 3));
            sp_n.assign(&nm);
            sp_m.assign(&m);
            let mut whole = DMatrix::from_element(n, q, f64::NAN);
            sp_n.right_mul(&s, &mut whole);
            let mut row = vec![f64::NAN; q];
            for i in 0..n {
                sp_n.product_row(&s_rows, i, &mut row);
                for (c, r) in row.iter().enumerate() {
                    assert_eq!(
                        r.to_bits(),
                        whole[(i, c)].to_bits(),
                        "seed {seed} ({i}, {c})"
                    );
                }
            }
            let start = pattern(3, q, seed + 600);
            let (mut want, mut got) = (start.clone(), start);
            sp_m.tr_mul_add(0.5, &whole, &mut want);
            let mut scratch = Vec::new();
            sp_m.tr_mul_product_add(0.5, &s_rows, &sp_n, &mut scratch, &mut got);
            for (g, w) in got.iter().zip(want.iter()) {
                assert_eq!(g.to_bits(), w.to_bits(), "seed {seed}: {g} vs {w}");
            }
        }
    }

    /// `right_mul` writes what clearing the product and `right_mul_add` write, bit for bit
    /// (signs of zeros included), over empty, sparse and dense columns and a dirty `out`.
    #[test]
    fn the_product_without_clearing_is_the_cleared_one_to_the_bit() {
        for seed in 0..50 {
            let mut m = pattern(9, 6, seed);
            m.column_mut(seed as usize % 6).fill(0.0);
            m.column_mut((seed as usize + 1) % 6).fill(-0.0);
            let s = pattern(5, 9, seed + 100).map(|v| if v == 0.0 { -0.0 } else { v * 1e6 });
            let mut sp = SparseColumns::new(9, 6);
            sp.assign(&m);
            let same = |got: &DMatrix<f64>, want: &DMatrix<f64>| {
                for (g, w) in got.iter().zip(want.iter()) {
                    assert_eq!(g.to_bits(), w.to_bits(), "seed {seed}: {g} vs {w}");
                }
            };
            let mut want = DMatrix::zeros(5, 6);
            sp.right_mul_add(&s, &mut want);
            let mut got = DMatrix::from_element(5, 6, f64::NAN);
            sp.right_mul(&s, &mut got);
            same(&got, &want);
        }
    }

    #[test]
    fn products_match_dense() {
        let m = pattern(7, 5, 1);
        let s = pattern(6, 7, 2);
        let x = pattern(7, 3, 3);
        let v = pattern(7, 1, 4);
        let mut sp = SparseColumns::new(7, 5);
        sp.assign(&m);
        assert!(sp.nnz() < 35);
        let mut out = DMatrix::from_element(6, 5, 3.0);
        sp.right_mul(&s, &mut out);
        assert!((&out - &s * &m).norm() < 1e-12);
        sp.right_mul_add(&s, &mut out);
        assert!((&out - 2.0 * &s * &m).norm() < 1e-12);
        let mut acc = DMatrix::from_element(5, 3, 1.0);
        sp.tr_mul_add(2.0, &x, &mut acc);
        let want = DMatrix::from_element(5, 3, 1.0) + 2.0 * m.transpose() * &x;
        assert!((&acc - want).norm() < 1e-12);
        let mut y = vec![0.5; 5];
        sp.tr_mul_vec_add(-1.0, v.as_slice(), &mut y);
        let want = DMatrix::from_element(5, 1, 0.5) - m.transpose() * &v;
        assert!(
            y.iter()
                .zip(want.iter())
                .all(|(a, b)| (a - b).abs() < 1e-12)
        );
    }

    /// Columns of many 8-row blocks (and a last partial one), refilled with a sparser, a
    /// denser and a pattern of single nonzeros among negative zeros, with NaNs and infinities:
    /// exactly the entries `!= 0.0`, in row order, each time.
    #[test]
    fn refills_hold_exactly_the_nonzeros() {
        let mut sp = SparseColumns::new(150, 4);
        for seed in [5, 6, 7] {
            let mut m = pattern(150, 4, seed);
            if seed == 5 {
                m.view_mut((0, 0), (100, 4)).fill(0.0);
            }
            if seed == 7 {
                // One entry per block at most, the rest negative zeros, and the special values.
                m = m.map(|v| if v.abs() < 0.95 { -0.0 } else { v });
                m[(3, 0)] = f64::NAN;
                m[(149, 1)] = f64::INFINITY;
                m[(8, 2)] = -f64::MIN_POSITIVE / 4.0;
            }
            sp.assign(&m);
            let nonzeros = m.iter().filter(|v| **v != 0.0).count();
            assert_eq!(sp.nnz(), nonzeros);
            let mut back = DMatrix::zeros(150, 4);
            for j in 0..4 {
                let (rows, vals) = sp.column(j);
                assert!(rows.windows(2).all(|w| w[0] < w[1]));
                for (&i, &v) in rows.iter().zip(vals) {
                    back[(i, j)] = v;
                }
            }
            let same = back.iter().zip(m.iter());
            assert!(
                same.clone()
                    .all(|(b, v)| b == v || (b.is_nan() && v.is_nan()))
            );
            assert!(same.filter(|(_, v)| **v != 0.0).count() == nonzeros);
        }
    }

    /// A refill by a support with unit columns (a shift register's, as the delayed plant
    /// declares) holds what a refill of the whole matrix holds, the units' ones included, and
    /// a refill by ranges reads nothing outside them (junk there is not picked up).
    #[test]
    fn a_refill_by_the_support_is_the_whole_refill() {
        let (n, c) = (12, 7);
        let mut m = pattern(n, c, 11);
        m.view_mut((4, 0), (n - 4, 3)).fill(0.0);
        let mut columns = vec![Column::Rows(0..4); 3];
        for j in 3..c {
            m.column_mut(j).fill(0.0);
            m[(j + 2, j)] = 1.0;
            columns.push(Column::Unit(j + 2));
        }
        let (mut whole, mut by_support) = (SparseColumns::new(n, c), SparseColumns::new(n, c));
        whole.assign(&m);
        by_support.assign_support(&m, &columns);
        for j in 0..c {
            assert_eq!(whole.column(j), by_support.column(j), "column {j}");
        }
        let mut junk = m.clone();
        junk.view_mut((4, 0), (n - 4, 3)).fill(7.0);
        let rows: Vec<Range<usize>> = (0..c)
            .map(|j| if j < 3 { 0..4 } else { j + 2..j + 3 })
            .collect();
        by_support.assign_within(&junk, Some(&rows));
        for j in 0..c {
            assert_eq!(
                whole.column(j),
                by_support.column(j),
                "column {j} by ranges"
            );
        }
    }

    /// Skipping the empty columns outside the occupied ones changes no bit of `y += α Mᵀ v`,
    /// `out += α Mᵀ X` and `out += α Mᵀ (S N)` (outputs holding zeros of both signs, factors of
    /// both signs and zero), against every column visited; nor for a matrix with no nonzero.
    #[test]
    fn skipping_empty_columns_changes_no_bit() {
        let (n, c) = (6, 9);
        for (seed, occupied) in [(1, 2..5), (2, 0..0), (3, 0..9), (4, 8..9)] {
            let mut m = pattern(n, c, seed);
            for j in (0..c).filter(|j| !occupied.contains(j)) {
                m.column_mut(j).fill(0.0);
            }
            let mut sp = SparseColumns::new(n, c);
            sp.assign(&m);
            let v: Vec<f64> = pattern(n, 1, seed + 10).iter().copied().collect();
            let x = pattern(n, 3, seed + 20);
            let s = {
                let a = pattern(n, n, seed + 30);
                &a + a.transpose()
            };
            let other = {
                let mut o = SparseColumns::new(n, 2);
                o.assign(&pattern(n, 2, seed + 40));
                o
            };
            for alpha in [1.0, 0.5, 0.0, -0.0, -1.0] {
                let start: Vec<f64> = (0..c).map(|j| [0.0, -0.0, 1.5][j % 3]).collect();
                let (mut y, mut want) = (start.clone(), start.clone());
                sp.tr_mul_vec_add(alpha, &v, &mut y);
                for (j, w) in want.iter_mut().enumerate() {
                    let (rows, vals) = sp.column(j);
                    let dot: f64 = rows.iter().zip(vals).map(|(&i, &a)| a * v[i]).sum();
                    *w += alpha * dot;
                }
                let bits = |y: &[f64]| y.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&y), bits(&want), "Mᵀ v, seed {seed}, α {alpha}");
                let dirty = DMatrix::from_fn(c, 3, |i, j| [0.0, -0.0, 2.0][(i + j) % 3]);
                let (mut out, mut want) = (dirty.clone(), dirty.clone());
                sp.tr_mul_add(alpha, &x, &mut out);
                for q in 0..3 {
                    for j in 0..c {
                        let (rows, vals) = sp.column(j);
                        let dot: f64 = rows.iter().zip(vals).map(|(&i, &a)| a * x[(i, q)]).sum();
                        want[(j, q)] += alpha * dot;
                    }
                }
                assert_eq!(
                    bits(out.as_slice()),
                    bits(want.as_slice()),
                    "Mᵀ X, α {alpha}"
                );
                let dirty = DMatrix::from_fn(c, 2, |i, j| [0.0, -0.0, 2.0][(i + j) % 3]);
                let (mut out, mut want) = (dirty.clone(), dirty.clone());
                let mut rows = Vec::new();
                sp.tr_mul_product_add(alpha, &s, &other, &mut rows, &mut out);
                let mut sn = DMatrix::zeros(n, 2);
                other.right_mul(&s, &mut sn);
                for q in 0..2 {
                    for j in 0..c {
                        let (idx, vals) = sp.column(j);
                        let dot: f64 = idx.iter().zip(vals).map(|(&i, &a)| a * sn[(i, q)]).sum();
                        want[(j, q)] += alpha * dot;
                    }
                }
                assert_eq!(
                    bits(out.as_slice()),
                    bits(want.as_slice()),
                    "Mᵀ S N, α {alpha}"
                );
            }
        }
    }
}
