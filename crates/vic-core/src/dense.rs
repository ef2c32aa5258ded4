//! Whole-matrix operations on contiguous storage as plain slice operations.
//!
//! nalgebra's `fill` and `copy_from` go element by element through a strided iterator, which
//! does not vectorise, and the 42-state delayed problem clears the cost's and the
//! linearisation's matrices at every knot, a large part of an ILQG iteration. On owned
//! (contiguous) storage the same operations are one `memset` or `memcpy`, with the same result.

use nalgebra::{DMatrix, Dim, IsContiguous, Matrix, RawStorage, RawStorageMut};

/// `m = 0`.
pub fn zero<R: Dim, C: Dim, S: RawStorageMut<f64, R, C> + IsContiguous>(
    m: &mut Matrix<f64, R, C, S>,
) {
    m.as_mut_slice().fill(0.0);
}

/// `dst = src` for matrices of one shape.
pub fn copy<R, C, S1, S2>(src: &Matrix<f64, R, C, S1>, dst: &mut Matrix<f64, R, C, S2>)
where
    R: Dim,
    C: Dim,
    S1: RawStorage<f64, R, C> + IsContiguous,
    S2: RawStorageMut<f64, R, C> + IsContiguous,
{
    debug_assert_eq!(src.shape(), dst.shape());
    dst.as_mut_slice().copy_from_slice(src.as_slice());
}

/// `dst = srcᵀ` on column-major storage.
pub fn transpose<R, C, S1, S2>(src: &Matrix<f64, R, C, S1>, dst: &mut Matrix<f64, C, R, S2>)
where
    R: Dim,
    C: Dim,
    S1: RawStorage<f64, R, C> + IsContiguous,
    S2: RawStorageMut<f64, C, R> + IsContiguous,
{
    let (r, c) = src.shape();
    debug_assert_eq!(dst.shape(), (c, r));
    if r == 0 || c == 0 {
        return;
    }
    let (sd, dd) = (src.as_slice(), dst.as_mut_slice());
    // Four columns of `src` at a time, each row of them one contiguous run of `dst`'s column:
    // four sequential reads and one short write per row instead of a scattered store per
    // entry (the delayed plant's 42×42 transposes are a large part of its backward pass).
    let mut j = 0;
    while j + 4 <= c {
        let col = |t: usize| &sd[(j + t) * r..(j + t + 1) * r];
        let rows = dd
            .chunks_exact_mut(c)
            .zip(col(0))
            .zip(col(1))
            .zip(col(2))
            .zip(col(3));
        for ((((out, &a), &b), &e), &f) in rows {
            out[j..j + 4].copy_from_slice(&[a, b, e, f]);
        }
        j += 4;
    }
    for j in j..c {
        for (out, &v) in dd.chunks_exact_mut(c).zip(&sd[j * r..(j + 1) * r]) {
            out[j] = v;
        }
    }
}

/// `m = (m + mᵀ) / 2` for a square matrix: each pair of entries across the diagonal replaced by
/// `0.5 (m_ij + m_ji)` (the same bits in either order), against round-off in a value Hessian.
/// Four columns at a time, as in [`transpose`]: the entries of those columns above the
/// diagonal pair with a contiguous run of four in each earlier column.
pub(crate) fn symmetrize(m: &mut DMatrix<f64>) {
    let n = m.nrows();
    debug_assert_eq!(m.ncols(), n);
    let d = m.as_mut_slice();
    let mut j = 0;
    while j + 4 <= n {
        // Columns 0..j hold the entries below the diagonal in rows j..j + 4; columns
        // j..j + 4, the ones above it.
        let (left, right) = d.split_at_mut(j * n);
        let (c0, rest) = right.split_at_mut(n);
        let (c1, rest) = rest.split_at_mut(n);
        let (c2, rest) = rest.split_at_mut(n);
        let c3 = &mut rest[..n];
        let upper = c0
            .iter_mut()
            .zip(c1.iter_mut())
            .zip(c2.iter_mut())
            .zip(c3.iter_mut());
        for (col, (((u0, u1), u2), u3)) in left.chunks_exact_mut(n).zip(upper) {
            for (l, u) in col[j..j + 4].iter_mut().zip([u0, u1, u2, u3]) {
                let v = 0.5 * (*l + *u);
                *l = v;
                *u = v;
            }
        }
        // The 4×4 block on the diagonal.
        for a in j..j + 4 {
            for b in a + 1..j + 4 {
                let v = 0.5 * (d[a * n + b] + d[b * n + a]);
                d[a * n + b] = v;
                d[b * n + a] = v;
            }
        }
        j += 4;
    }
    for j in j..n {
        for i in 0..j {
            let v = 0.5 * (d[i * n + j] + d[j * n + i]);
            d[i * n + j] = v;
            d[j * n + i] = v;
        }
    }
}

/// Lanes of [`TransposedProduct`]: output columns computed side by side.
const LANES: usize = 4;

/// `c = aᵀ b` or `c += aᵀ b` for dynamically sized matrices, with the bits of nalgebra's
/// `c.gemm_tr(1.0, a, b, β)` (β = 0 or 1), computed faster.
///
/// Why: nalgebra computes each entry as a dot product of two columns on its own (eight partial
/// sums over blocks of eight rows, then the rest), one call per entry, and the SOOC backward
/// pass forms `Aᵀ (V A)` on the VSA arm's 44 moment states at every knot, a large part of a
/// plan. Here [`LANES`] entries of a row of `c` are computed side by side, each with exactly
/// nalgebra's partial sums in nalgebra's order (the lanes are independent entries, not parts of
/// one sum), so the compiler vectorises across entries and no rounding changes. `b` is read from
/// a copy in blocks of [`LANES`] columns kept in the workspace (no allocation once sized).
#[derive(Debug, Clone, Default)]
pub(crate) struct TransposedProduct {
    /// `b` in blocks of [`LANES`] columns, each block row by row:
    /// `blocks[(jb · rows + r) · LANES + l] = b[(r, jb · LANES + l)]`, padded with 0.
    blocks: Vec<f64>,
}

impl TransposedProduct {
    /// A workspace for `b` of up to `rows × cols` entries (it grows if a larger `b` comes).
    pub fn new(rows: usize, cols: usize) -> Self {
        TransposedProduct {
            blocks: vec![0.0; rows * cols.div_ceil(LANES) * LANES],
        }
    }

    /// `c = aᵀ b` (`accumulate` false) or `c += aᵀ b` (true).
    pub fn apply(
        &mut self,
        c: &mut DMatrix<f64>,
        a: &DMatrix<f64>,
        b: &DMatrix<f64>,
        accumulate: bool,
    ) {
        let (r, p) = a.shape();
        let q = b.ncols();
        assert_eq!(b.nrows(), r, "aᵀ b: a and b differ in rows");
        assert_eq!(c.shape(), (p, q), "aᵀ b: c has the wrong shape");
        if r == 0 {
            // Empty sums (no blocks to cut the rows into): nalgebra's own answer.
            c.gemm_tr(1.0, a, b, if accumulate { 1.0 } else { 0.0 });
            return;
        }
        let len = r * q.div_ceil(LANES) * LANES;
        if self.blocks.len() < len {
            self.blocks.resize(len, 0.0);
        }
        let bs = b.as_slice();
        for (jb, block) in self.blocks[..len].chunks_exact_mut(r * LANES).enumerate() {
            for (row, lanes) in block.chunks_exact_mut(LANES).enumerate() {
                for (l, v) in lanes.iter_mut().enumerate() {
                    let j = jb * LANES + l;
                    *v = if j < q { bs[j * r + row] } else { 0.0 };
                }
            }
        }
        let blocks = &self.blocks[..len];
        #[cfg(target_arch = "x86_64")]
        if crate::wide::enabled() {
            // SAFETY: `enabled` is true only where the CPU reported AVX2.
            unsafe { product_avx2(c, a, blocks, accumulate) };
            return;
        }
        product(c, a, blocks, accumulate);
    }
}

/// [`product`] compiled for AVX2 (see [`crate::wide`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn product_avx2(c: &mut DMatrix<f64>, a: &DMatrix<f64>, blocks: &[f64], accumulate: bool) {
    product(c, a, blocks, accumulate);
}

/// The kernel of [`TransposedProduct::apply`]: entry `(i, j)` is nalgebra's `dotx` of column `i`
/// of `a` and column `j` of `b` (partial sums 0–7 over whole blocks of eight rows, then
/// `0 + (s0 + s4) + (s1 + s5) + (s2 + s6) + (s3 + s7)`, then the remaining rows one by one),
/// added to `c` as nalgebra's `gemv` adds it (`1·dot + 1·c`).
#[inline(always)]
fn product(c: &mut DMatrix<f64>, a: &DMatrix<f64>, blocks: &[f64], accumulate: bool) {
    let (r, p) = a.shape();
    let q = c.ncols();
    let whole = r / 8 * 8;
    let a = a.as_slice();
    let c = c.as_mut_slice();
    for (jb, block) in blocks.chunks_exact(r * LANES).enumerate() {
        let (head, tail) = block.split_at(whole * LANES);
        let j0 = jb * LANES;
        for (i, col) in a.chunks_exact(r).enumerate() {
            let (col_head, col_tail) = col.split_at(whole);
            let mut res = [0.0f64; LANES];
            if whole > 0 {
                let mut s = [[0.0f64; LANES]; 8];
                for (x8, b8) in col_head.chunks_exact(8).zip(head.chunks_exact(8 * LANES)) {
                    for (t, st) in s.iter_mut().enumerate() {
                        for l in 0..LANES {
                            st[l] += x8[t] * b8[t * LANES + l];
                        }
                    }
                }
                for l in 0..LANES {
                    res[l] += s[0][l] + s[4][l];
                    res[l] += s[1][l] + s[5][l];
                    res[l] += s[2][l] + s[6][l];
                    res[l] += s[3][l] + s[7][l];
                }
            }
            // With no whole block nalgebra adds eight zero partial sums to 0: +0, as here.
            for (&x, lanes) in col_tail.iter().zip(tail.chunks_exact(LANES)) {
                for l in 0..LANES {
                    res[l] += x * lanes[l];
                }
            }
            for (l, &v) in res.iter().enumerate().take(q - j0) {
                let e = &mut c[(j0 + l) * p + i];
                *e = if accumulate { v + *e } else { v };
            }
        }
    }
}

/// nalgebra multiplies matrices this small in every dimension with its own loops, and larger ones
/// with matrixmultiply (`blas_uninit.rs`, "threshold determined empirically").
const SMALL_DIM: usize = 5;

/// `c = a b` (`accumulate` false) or `c += a b` (true), without allocating.
///
/// Why: nalgebra hands a product larger than 5×5 in every dimension to matrixmultiply, which
/// allocates its packing buffers at every call; in the SOOC iteration that would be an
/// allocation per knot and backward pass on the impedance arm (`V A`) and dozens per knot on the
/// VSA arm (its moment step's 8×8 products). Here each entry is matrixmultiply's own sum on CPUs
/// with FMA (the kernel it picks there): the products added one after another by fused
/// multiply-adds from +0 in the order of `k`, then, to accumulate, one addition to `c`. So the
/// plans keep their bits where matrixmultiply ran its FMA kernel; where it ran its plain AVX
/// kernel (no FMA) this kernel is not used: without AVX2 and FMA (or with the wide kernels
/// forbidden, [`crate::wide`]) the product is nalgebra's, allocation included. Smaller
/// products (any dimension ≤ 5) are nalgebra's loops to the bit ([`small_product`]).
pub fn multiply(c: &mut DMatrix<f64>, a: &DMatrix<f64>, b: &DMatrix<f64>, accumulate: bool) {
    let (m, k) = a.shape();
    let n = b.ncols();
    assert_eq!(b.nrows(), k, "a b: a's columns differ from b's rows");
    assert_eq!(c.shape(), (m, n), "a b: c has the wrong shape");
    if m <= SMALL_DIM || n <= SMALL_DIM || k <= SMALL_DIM {
        #[cfg(target_arch = "x86_64")]
        if crate::wide::enabled() {
            // SAFETY: `enabled` is true only where the CPU reported AVX2.
            unsafe { small_product_avx2(c, a, b, accumulate) };
            return;
        }
        small_product(c, a, b, accumulate);
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if crate::wide::enabled() && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU reported AVX2 and FMA.
        unsafe { fused_product(c, a, b, accumulate) };
        return;
    }
    // Without FMA (or with the wide kernels forbidden) matrixmultiply's own kernels are faster
    // than a `mul_add` call per term, and round as nalgebra's product does.
    c.gemm(1.0, a, b, if accumulate { 1.0 } else { 0.0 });
}

/// [`small_product`] compiled for AVX2 (see [`crate::wide`]; no FMA: the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn small_product_avx2(c: &mut DMatrix<f64>, a: &DMatrix<f64>, b: &DMatrix<f64>, accumulate: bool) {
    small_product(c, a, b, accumulate);
}

/// nalgebra 0.35's `c.gemm(1, a, b, β)` for the products it keeps to itself (a dimension ≤ 5), to
/// the bit, on contiguous columns: per column `j` of `c`, nalgebra's `gemv`, whose first term
/// is `(1 · a_i0) b_0j`, alone for β = 0 or plus `1 · c_ij` for β = 1, and every later one
/// `(1 · a_ik) b_kj + 1 · c_ij` (the products by 1 are exact, no operation is fused). nalgebra
/// walks the same columns through run-time strides and does not vectorise them; here each
/// column of `a` is one `axpy` over contiguous memory (the SOOC moment step's 4×4 products and
/// the backward pass's `V B`, `Q_uu K` on the arm).
#[inline(always)]
fn small_product(c: &mut DMatrix<f64>, a: &DMatrix<f64>, b: &DMatrix<f64>, accumulate: bool) {
    let (m, k) = a.shape();
    let (ad, bd) = (a.as_slice(), b.as_slice());
    let cd = c.as_mut_slice();
    if k == 0 {
        if !accumulate {
            cd.fill(0.0);
        }
        return;
    }
    // The short columns of the paper's plants with their length a constant (a loop over four
    // entries with a run-time length costs more than nalgebra's unchecked one).
    match m {
        0 => {}
        2 => small_columns::<2>(cd, ad, bd, k, accumulate),
        4 => small_columns::<4>(cd, ad, bd, k, accumulate),
        8 => small_columns::<8>(cd, ad, bd, k, accumulate),
        _ => {
            for (col, bj) in cd.chunks_exact_mut(m).zip(bd.chunks_exact(k)) {
                let mut terms = ad.chunks_exact(m).zip(bj);
                if let Some((a0, &b0)) = terms.next() {
                    for (y, &x) in col.iter_mut().zip(a0) {
                        *y = if accumulate { *y + x * b0 } else { x * b0 };
                    }
                }
                for (ak, &v) in terms {
                    for (y, &x) in col.iter_mut().zip(ak) {
                        *y += x * v;
                    }
                }
            }
        }
    }
}

/// [`small_product`] for columns of `M` entries (`k ≥ 1`).
#[inline(always)]
fn small_columns<const M: usize>(cd: &mut [f64], ad: &[f64], bd: &[f64], k: usize, acc: bool) {
    let (a_cols, _) = ad.as_chunks::<M>();
    let (c_cols, _) = cd.as_chunks_mut::<M>();
    for (col, bj) in c_cols.iter_mut().zip(bd.chunks_exact(k)) {
        let mut y = if acc { *col } else { [0.0; M] };
        for (i, (ak, &v)) in a_cols.iter().zip(bj).enumerate() {
            for (y, &x) in y.iter_mut().zip(ak) {
                *y = if i == 0 && !acc { x * v } else { *y + x * v };
            }
        }
        *col = y;
    }
}

/// Rows and columns of `c` [`fused_product`] computes at once: eight independent chains of
/// fused multiply-adds in registers (two 256-bit registers of rows times four columns; four
/// rows, one register, at the bottom edge).
#[cfg(target_arch = "x86_64")]
const BLOCK_ROWS: usize = 8;
#[cfg(target_arch = "x86_64")]
const BLOCK_COLS: usize = 4;

/// The kernel of [`multiply`]: blocks of [`BLOCK_ROWS`] × [`BLOCK_COLS`] entries of `c`, each
/// entry its own sum over `k` in order (so the blocking changes no rounding).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn fused_product(c: &mut DMatrix<f64>, a: &DMatrix<f64>, b: &DMatrix<f64>, accumulate: bool) {
    let (m, k) = a.shape();
    let n = b.ncols();
    let (av, bv, cv) = (a.as_slice(), b.as_slice(), c.as_mut_slice());
    let mut j0 = 0;
    while j0 < n {
        let cols = BLOCK_COLS.min(n - j0);
        let mut i0 = 0;
        while i0 < m {
            // Eight rows, or four (one register), or what is left.
            let rows = match m - i0 {
                r if r >= BLOCK_ROWS => BLOCK_ROWS,
                r if r >= 4 => 4,
                r => r,
            };
            let mut acc = [[0.0f64; BLOCK_ROWS]; BLOCK_COLS];
            match rows {
                BLOCK_ROWS => block_fma::<2>(&mut acc, av, bv, (m, k), (i0, j0), cols),
                4 => block_fma::<1>(&mut acc, av, bv, (m, k), (i0, j0), cols),
                _ => partial_block(&mut acc, av, bv, (m, k), (i0, j0), (rows, cols)),
            }
            for (l, acc_l) in acc.iter().enumerate().take(cols) {
                let out = &mut cv[(j0 + l) * m + i0..(j0 + l) * m + i0 + rows];
                if accumulate {
                    for (o, &s) in out.iter_mut().zip(acc_l) {
                        *o += s;
                    }
                } else {
                    out.copy_from_slice(&acc_l[..rows]);
                }
            }
            i0 += rows;
        }
        j0 += cols;
    }
}

/// The last rows (fewer than four) of [`fused_product`] entry by entry (`mul_add`, one FMA
/// instruction here, the same single rounding as the vector one).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn partial_block(
    acc: &mut [[f64; BLOCK_ROWS]; BLOCK_COLS],
    av: &[f64],
    bv: &[f64],
    (m, k): (usize, usize),
    (i0, j0): (usize, usize),
    (rows, cols): (usize, usize),
) {
    for p in 0..k {
        let col = &av[p * m + i0..p * m + i0 + rows];
        for (l, acc_l) in acc.iter_mut().enumerate().take(cols) {
            let bpj = bv[(j0 + l) * k + p];
            for (s, &x) in acc_l.iter_mut().zip(col) {
                *s = x.mul_add(bpj, *s);
            }
        }
    }
}

/// A block of `4 R` rows (`R` 256-bit registers per column) and `cols` ≤ 4 columns of
/// [`fused_product`] in registers: per `k`, `R` loads of `a`'s column, a broadcast of `b` per
/// column, `R` fused multiply-adds per column.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn block_fma<const R: usize>(
    acc: &mut [[f64; BLOCK_ROWS]; BLOCK_COLS],
    av: &[f64],
    bv: &[f64],
    (m, k): (usize, usize),
    (i0, j0): (usize, usize),
    cols: usize,
) {
    use std::arch::x86_64::*;
    assert!(R <= 2 && i0 + 4 * R <= m && av.len() >= m * k && bv.len() >= (j0 + cols) * k);
    let mut reg = [[_mm256_setzero_pd(); 2]; BLOCK_COLS];
    for p in 0..k {
        let mut a = [_mm256_setzero_pd(); 2];
        for (r, ar) in a.iter_mut().enumerate().take(R) {
            // SAFETY: rows i0 + 4r .. i0 + 4r + 4 of column p of `a` lie in `av` (asserted).
            *ar = unsafe { _mm256_loadu_pd(av.as_ptr().add(p * m + i0 + 4 * r)) };
        }
        for (l, reg_l) in reg.iter_mut().enumerate().take(cols) {
            let bpj = _mm256_set1_pd(bv[(j0 + l) * k + p]);
            for r in 0..R {
                reg_l[r] = _mm256_fmadd_pd(a[r], bpj, reg_l[r]);
            }
        }
    }
    for (acc_l, reg_l) in acc.iter_mut().zip(&reg).take(cols) {
        for r in 0..R {
            // SAFETY: each row of `acc` holds eight doubles, r ≤ 1.
            unsafe { _mm256_storeu_pd(acc_l.as_mut_ptr().add(4 * r), reg_l[r]) };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A matrix of awkward values (no two alike, mixed signs and magnitudes) from a seed.
    fn awkward(rows: usize, cols: usize, seed: u64) -> DMatrix<f64> {
        let mut state = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        DMatrix::from_fn(rows, cols, |_, _| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (state >> 11) as f64 / (1u64 << 53) as f64;
            (u - 0.4) * 10f64.powi(((state >> 7) % 7) as i32 - 3)
        })
    }

    /// `transpose` is nalgebra's transpose, and `symmetrize` averages every pair across the
    /// diagonal once (`0.5 (a + b)`, as an entry-by-entry loop does), leaving the diagonal: on
    /// every size around the blocks of four and the delayed plant's 42, with zeros of both
    /// signs among the entries.
    #[test]
    fn blocked_transpose_and_symmetrize_move_every_entry() {
        for (r, c) in [
            (0, 3),
            (1, 1),
            (3, 5),
            (4, 4),
            (5, 9),
            (8, 3),
            (13, 13),
            (42, 42),
        ] {
            let mut m = awkward(r, c, (r * 100 + c) as u64);
            if r > 2 && c > 2 {
                m[(1, 2)] = -0.0;
                m[(2, 1)] = 0.0;
            }
            let mut t = DMatrix::from_element(c, r, f64::NAN);
            transpose(&m, &mut t);
            let want = m.transpose();
            assert!(
                t.iter()
                    .zip(want.iter())
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
            if r == c {
                let mut got = m.clone();
                symmetrize(&mut got);
                for i in 0..r {
                    for j in 0..r {
                        let want = if i == j {
                            m[(i, i)]
                        } else {
                            0.5 * (m[(i, j)] + m[(j, i)])
                        };
                        assert_eq!(got[(i, j)].to_bits(), want.to_bits(), "{r}: ({i}, {j})");
                    }
                }
            }
        }
    }

    /// Bit for bit nalgebra's `gemm` (β = 0 and 1): where the kernel runs (AVX2 and FMA) it sums
    /// as matrixmultiply's FMA kernels do; elsewhere, and below 6×6, the product is `gemm`
    /// itself. No allocation: `tests/sooc_workspace.rs` counts.
    #[test]
    fn multiply_has_matrixmultiplys_bits() {
        let shapes = [
            (8, 8, 8),
            (14, 14, 14),
            (44, 44, 44),
            (44, 8, 44),
            (6, 6, 6),
            (9, 7, 13),
            (4, 4, 4),
            (14, 14, 4),
            (65, 8, 8),
            (7, 9, 6),
            (15, 6, 11),
            (12, 6, 7),
            // nalgebra's own loops (a dimension ≤ 5): the SOOC step's and backward pass's.
            (4, 4, 14),
            (14, 4, 4),
            (2, 2, 2),
            (8, 4, 8),
            (8, 8, 2),
            (1, 5, 3),
            (5, 1, 7),
            (3, 0, 2),
            (0, 3, 2),
        ];
        for &(m, k, n) in &shapes {
            for wide in [false, true] {
                crate::wide::set_enabled(wide);
                for accumulate in [false, true] {
                    let a = awkward(m, k, 1 + m as u64);
                    let b = awkward(k, n, 2 + n as u64);
                    let c0 = awkward(m, n, 3);
                    let mut want = c0.clone();
                    want.gemm(1.0, &a, &b, if accumulate { 1.0 } else { 0.0 });
                    let mut got = c0.clone();
                    multiply(&mut got, &a, &b, accumulate);
                    for (g, w) in got.iter().zip(want.iter()) {
                        assert_eq!(g.to_bits(), w.to_bits(), "{m}x{k}x{n} acc {accumulate}");
                    }
                }
            }
        }
        crate::wide::set_enabled(true);
    }

    /// Every shape the solvers use and the edges of the kernel's blocks: fewer than eight rows,
    /// whole blocks with and without a rest, columns not a multiple of the lanes. Bit for bit
    /// nalgebra's `gemm_tr` with β = 0 and β = 1, on both instruction sets.
    #[test]
    fn the_product_has_nalgebras_bits() {
        let shapes = [
            (1, 1, 1),
            (4, 4, 4),
            (4, 14, 14),
            (14, 14, 14),
            (14, 4, 14),
            (14, 4, 4),
            (8, 3, 5),
            (16, 7, 9),
            (44, 44, 44),
            (44, 4, 44),
            (44, 4, 4),
            (4, 44, 44),
            (23, 6, 2),
            (0, 3, 2),
        ];
        let wide_before = crate::wide::enabled();
        for wide in [false, true] {
            crate::wide::set_enabled(wide);
            let mut ws = TransposedProduct::new(2, 2);
            for (k, &(r, p, q)) in shapes.iter().enumerate() {
                let a = awkward(r, p, 3 * k as u64);
                let b = awkward(r, q, 3 * k as u64 + 1);
                let c0 = awkward(p, q, 3 * k as u64 + 2);
                for accumulate in [false, true] {
                    let mut want = c0.clone();
                    want.gemm_tr(1.0, &a, &b, if accumulate { 1.0 } else { 0.0 });
                    let mut got = c0.clone();
                    ws.apply(&mut got, &a, &b, accumulate);
                    for (g, w) in got.iter().zip(want.iter()) {
                        assert_eq!(
                            g.to_bits(),
                            w.to_bits(),
                            "{r}x{p}ᵀ · {r}x{q}, accumulate {accumulate}, wide {wide}: {g} vs {w}"
                        );
                    }
                }
            }
        }
        crate::wide::set_enabled(wide_before);
    }
}
