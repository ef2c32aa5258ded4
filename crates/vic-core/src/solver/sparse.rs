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

use crate::dense::zero;
use crate::dynamics::{Column, Linearization, NoiseKind, StateSupport};
use nalgebra::DMatrix;
use std::ops::Range;

/// A matrix stored by its nonzeros, column by column (compressed sparse column).
#[derive(Debug, Clone)]
pub(crate) struct SparseColumns {
    nrows: usize,
    /// Entries of column `j` are `start[j]..start[j + 1]`.
    start: Vec<usize>,
    /// The nonzeros' rows and values, column after column. Room is reserved ahead (for every
    /// entry, or for what a model's support allows: [`SparseLinearization::make_room`]) but
    /// only the nonzeros are ever written: the 42-state delayed plant stores 46 of 1764 entries of
    /// `A` per knot, and a workspace that touched all of them would spend a large part of a
    /// stochastic plan faulting in and clearing memory it never read.
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
    #[cfg(test)]
    pub(crate) fn new(nrows: usize, ncols: usize) -> Self {
        SparseColumns {
            nrows,
            start: vec![0; ncols + 1],
            row: Vec::with_capacity(nrows * ncols),
            val: Vec::with_capacity(nrows * ncols),
            occupied: 0..0,
        }
    }

    /// An `nrows × ncols` matrix without room for its nonzeros: see [`SparseColumns::make_room`].
    pub(crate) fn without_room(nrows: usize, ncols: usize) -> Self {
        SparseColumns {
            nrows,
            start: vec![0; ncols + 1],
            row: Vec::new(),
            val: Vec::new(),
            occupied: 0..0,
        }
    }

    /// Room for `nnz` nonzeros in all (allocates only if there is less).
    pub(crate) fn make_room(&mut self, nnz: usize) {
        self.row.reserve_exact(nnz.saturating_sub(self.row.len()));
        self.val.reserve_exact(nnz.saturating_sub(self.val.len()));
    }

    /// Number of columns.
    pub fn ncols(&self) -> usize {
        self.start.len() - 1
    }

    /// Number of stored (nonzero) entries.
    pub(crate) fn nnz(&self) -> usize {
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
    pub(crate) fn assign(&mut self, m: &DMatrix<f64>) {
        self.assign_within(m, None);
    }

    /// [`SparseColumns::assign`] reading column `j` in rows `rows[j]` only, when given: the
    /// caller knows the entries outside are zero ([`StateSupport`]), and the result is the same.
    pub(crate) fn assign_within(&mut self, m: &DMatrix<f64>, rows: Option<&[Range<usize>]>) {
        debug_assert!(rows.is_none_or(|r| r.len() == m.ncols()));
        self.assign_columns(m, |j| match rows {
            Some(r) => Column::Rows(r[j].clone()),
            None => Column::Rows(0..m.nrows()),
        });
    }

    /// [`SparseColumns::assign`] reading column `j` where `columns[j]` says it can be nonzero,
    /// and a unit column's one without reading it: the caller knows the entries outside are
    /// zero and the unit entries one ([`StateSupport`]), and the result is the same.
    pub(crate) fn assign_support(&mut self, m: &DMatrix<f64>, columns: &[Column]) {
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
    pub(crate) fn product_row(&self, s_rows: &DMatrix<f64>, i: usize, out: &mut [f64]) {
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
    pub(crate) fn tr_mul_product_add(
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
pub(crate) trait ColumnProducts {
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
/// (a filtering branch is a sizeable part of a solve of the two-link reach).
#[inline(always)]
pub(crate) fn nonzero_dot<const R: usize>(m: &[f64; R], x: &[f64]) -> f64 {
    m.iter()
        .zip(&x[..R])
        .map(|(&a, &x)| if a != 0.0 { a * x } else { -0.0 })
        .sum()
}

/// The nonzeros of one knot's `A`, `B` and noise Jacobians `Cx_i`, `Cu_i`.
#[derive(Debug, Clone)]
pub(crate) struct SparseLinearization {
    pub a: SparseColumns,
    pub b: SparseColumns,
    pub cx: Vec<SparseColumns>,
    pub cu: Vec<SparseColumns>,
}

impl SparseLinearization {
    /// A linearisation's patterns without room for any nonzero yet: see
    /// [`SparseLinearization::make_room`].
    pub fn new(nx: usize, nu: usize, nw: usize) -> Self {
        SparseLinearization {
            a: SparseColumns::without_room(nx, nx),
            b: SparseColumns::without_room(nx, nu),
            cx: (0..nw)
                .map(|_| SparseColumns::without_room(nx, nx))
                .collect(),
            cu: (0..nw)
                .map(|_| SparseColumns::without_room(nx, nu))
                .collect(),
        }
    }

    /// Room for every nonzero a model with this `support` can have, or for every entry when
    /// it has none: the refills then allocate nothing. Room once made is kept. The delayed
    /// plant's 46 nonzeros of `A` and 8 of each `Cx_i` take 1 KB a knot where room for every
    /// entry would take 84 KB: the backward pass's few lines per knot would lie scattered over
    /// tens of MB of address space, and a noisy delayed plan would wait on page-table misses
    /// (fitting the room gains what putting the heap on huge pages gains).
    pub(crate) fn make_room(&mut self, support: Option<&StateSupport>) {
        let len = |c: &Column| match c {
            Column::Rows(r) => r.len(),
            Column::Unit(_) => 1,
        };
        let (nx, nu) = (self.a.nrows, self.b.ncols());
        match support {
            Some(s) => {
                self.a.make_room(s.a.iter().map(len).sum());
                self.b.make_room(s.b.iter().map(len).sum());
                for m in &mut self.cx {
                    m.make_room(s.cx.iter().map(|r| r.len()).sum());
                }
                for m in &mut self.cu {
                    m.make_room(s.cu.iter().map(|r| r.len()).sum());
                }
            }
            None => {
                self.a.make_room(nx * nx);
                self.b.make_room(nx * nu);
                for m in &mut self.cx {
                    m.make_room(nx * nx);
                }
                for m in &mut self.cu {
                    m.make_room(nx * nu);
                }
            }
        }
    }

    /// Refills from a dense linearisation (the noise Jacobians only when state-dependent),
    /// reading the Jacobians only within the model's `support` when it has one.
    pub(crate) fn assign(&mut self, lin: &Linearization, support: Option<&StateSupport>) {
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
pub(crate) mod tests;
